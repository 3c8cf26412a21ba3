"""The host-bridge wire protocol: what is accepted, and every kind of bad datagram dropped and counted."""

import struct
import zlib

import numpy as np
import pytest

from rehabkit.hardware.link.protocol import COMMAND, HEADER, STATE, VERSION, Receiver, encode, newer


def _state(seq, n=6, sent_at=100.0, robot=7):
    return encode(STATE, robot, seq, np.arange(3 * n, dtype=float).reshape(3, n), sent_at=sent_at, echo=99.5,
                  status=1)


def test_round_trip_keeps_every_field():
    rx = Receiver(STATE, robot=7, joints=6)
    msg = rx.accept(_state(1))
    assert msg.seq == 1 and msg.sent_at == 100.0 and msg.echo == 99.5 and msg.status == 1
    np.testing.assert_array_equal(msg.values, np.arange(18.0).reshape(3, 6))
    cmd = encode(COMMAND, 7, 5, np.array([0.5, -1.0]), sent_at=3.0)
    got = Receiver(COMMAND, robot=7, joints=2).accept(cmd)
    np.testing.assert_array_equal(got.values, [0.5, -1.0])


def test_duplicates_and_late_arrivals_are_dropped_and_counted():
    rx = Receiver(STATE, robot=7, joints=6)
    accepted = [rx.accept(_state(s)) is not None for s in (1, 2, 2, 4, 3, 5)]
    assert accepted == [True, True, False, True, False, True]
    assert rx.dropped == {"duplicate": 1, "out-of-order": 1} and rx.accepted == 4


def test_sequence_numbers_wrap_around():
    assert newer(0, 0xFFFFFFFF) and newer(5, 0xFFFFFFF0) and not newer(0xFFFFFFF0, 5)
    rx = Receiver(STATE, robot=7, joints=6)
    assert rx.accept(_state(0xFFFFFFFF)) is not None and rx.accept(_state(0x1_0000_0000)) is not None  # seq 0


def test_stale_messages_are_dropped():
    rx = Receiver(STATE, robot=7, joints=6, max_age=0.005)
    assert rx.accept(_state(1, sent_at=10.0), now=10.004) is not None
    assert rx.accept(_state(2, sent_at=10.0), now=10.006) is None
    assert rx.dropped["stale"] == 1


def _forge(data: bytes, offset: int, fmt: str, value) -> bytes:
    """Change one header field and re-seal the checksum (a well-formed but wrong message)."""
    body = bytearray(data[:-4])
    struct.pack_into(fmt, body, offset, value)
    return bytes(body) + struct.pack("<I", zlib.crc32(bytes(body)))


@pytest.mark.parametrize("mutate, reason", [
    (lambda d: d[:20], "length"),  # shorter than a header and a checksum
    (lambda d: d[:-1], "checksum"),  # (the trailer is checked first: a datagram cut or padded no longer matches it)
    (lambda d: d + b"\0", "checksum"),
    (lambda d: _forge(d, HEADER.size - 4, "<I", 5), "authenticated"),  # sealed in a session: no key here to check it
    (lambda d: d[:30] + bytes([d[30] ^ 0xFF]) + d[31:], "checksum"),  # a flipped bit in the body
    (lambda d: _forge(d, 0, "<2s", b"XX"), "magic"),
    (lambda d: _forge(d, 2, "<B", VERSION + 1), "version"),
    (lambda d: _forge(d, 3, "<B", COMMAND), "kind"),
    (lambda d: _forge(d, 4, "<I", 8), "robot"),
    (lambda d: _forge(d, HEADER.size, "<d", float("nan")), "non-finite"),
])
def test_malformed_or_forged_datagrams_are_dropped(mutate, reason):
    rx = Receiver(STATE, robot=7, joints=6)
    assert rx.accept(mutate(_state(1))) is None
    assert rx.dropped == {reason: 1} and rx.last_seq is None  # nothing of it was taken


def test_a_random_byte_stream_never_gets_through(rng):
    rx = Receiver(STATE, robot=7, joints=6)
    good = _state(1)
    for _ in range(2000):
        junk = bytes(rng.integers(0, 256, len(good), dtype=np.uint8))
        assert rx.accept(junk) is None
    assert rx.accepted == 0 and sum(rx.dropped.values()) == 2000


def test_a_wrong_joint_count_is_refused():
    assert Receiver(STATE, robot=7, joints=5).accept(_state(1)) is None
    with pytest.raises(ValueError, match="takes"):
        encode(STATE, 7, 1, np.zeros(6))


def test_measured_only_joints_travel_with_the_state_and_their_count_is_checked():
    values = np.arange(18, dtype=float).reshape(3, 6)
    data = encode(STATE, 7, 1, values, sent_at=1.0, measured=np.array([0.25, -0.5]))
    got = Receiver(STATE, robot=7, joints=6, measured=2).accept(data)
    np.testing.assert_array_equal(got.values, values)
    np.testing.assert_array_equal(got.measured, [0.25, -0.5])
    # a receiver expecting another count drops it (a different robot model on the other side)
    rx = Receiver(STATE, robot=7, joints=6, measured=1)
    assert rx.accept(data) is None and rx.dropped["joints"] == 1
    with pytest.raises(ValueError, match="measured-only"):
        encode(COMMAND, 7, 1, np.zeros(6), measured=np.zeros(1))


def test_instrument_values_travel_with_the_state_and_their_count_is_checked():
    values = np.arange(18, dtype=float).reshape(3, 6)
    ft = np.array([1.0, -2.0, 30.5, 0.1, 0.2, -0.3])  # a force-torque sensor's force and torque
    data = encode(STATE, 7, 1, values, sent_at=1.0, measured=np.array([0.25]), instruments=ft)
    got = Receiver(STATE, robot=7, joints=6, measured=1, instruments=6).accept(data)
    np.testing.assert_array_equal(got.measured, [0.25])
    np.testing.assert_array_equal(got.instruments, ft)
    # a bridge started without the run's sensors sends none: dropped, and the reason says so
    rx = Receiver(STATE, robot=7, joints=6, measured=1, instruments=6)
    assert rx.accept(encode(STATE, 7, 2, values, measured=np.array([0.25]))) is None
    assert rx.dropped == {"instruments": 1}
    truncated = _forge(data[:-12], 0, "<2s", b"RK")  # (resealed: a well-formed datagram one value short)
    assert rx.accept(truncated) is None and rx.dropped["joints"] == 1
