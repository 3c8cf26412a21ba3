"""The robot link's decoders against what anyone may send: junk, flipped bits, sealed states altered, handshakes —
none raises, nothing not sealed with the robot's key is let in (hypothesis, the same 2000 datagrams every run: 200
examples of 10 each — the engine's own work, ~2 ms an example, was most of the test's time at one datagram each)."""

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from rehabkit.hardware.link.protocol import COMMAND, STATE, Receiver, encode
from rehabkit.hardware.security.gate import BridgeGate
from rehabkit.hardware.security.handshake import HostHandshake, peek_kind
from rehabkit.hardware.security.keys import new_key
from tests.test_link_security import HOST, _shake


@pytest.fixture(scope="module")
def linked(tmp_path_factory):
    """A key, a bridge's gate and the host's session with it (one handshake for all the fuzzed inputs)."""
    key = new_key("hit-1", tmp_path_factory.mktemp("key") / "hit-1.key")
    gate = BridgeGate(key, 1)
    return key, gate, _shake(key, gate)[0]


@settings(max_examples=200, deadline=None, database=None, derandomize=True,  # (the same examples every run)
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(datagrams=st.lists(st.tuples(st.binary(max_size=200),
                                    st.lists(st.integers(0, 8 * 120 - 1), min_size=1, max_size=4),
                                    st.sampled_from(["junk", "state", "command", "hello"])), min_size=10, max_size=10))
def test_the_decoder_and_the_handshake_never_raise_and_never_let_in_what_was_not_sealed(linked, datagrams):
    for junk, flips, head in datagrams:
        _fuzzed(linked, junk, flips, head)


def _fuzzed(linked, junk: bytes, flips: list[int], head: str) -> None:
    """One datagram: ``head``'s kind (``junk`` itself, or a real one made now) with the bits ``flips`` flipped."""
    key, gate, session = linked
    base = {"junk": lambda: junk, "state": lambda: _sealed_state(session),
            "command": lambda: encode(COMMAND, 1, 5, np.ones(6)),
            "hello": lambda: HostHandshake(key, 1).next(1)}[head]()
    data = bytearray(base)
    for bit in flips:
        if bit < 8 * len(data):
            data[bit // 8] ^= 1 << bit % 8
    data = bytes(data)
    if peek_kind(data) in (5, 6, 7, 8, 9, 10):
        gate.reply(data, HOST)  # answered or refused, never raises
        assert gate.session.id == session.id  # no session is opened without the key
    else:
        opened = gate.open(data, HOST)[0]
        assert opened is None or head == "state" and data == base  # (untouched, the host's own: authentic)
    Receiver(STATE, 1, 6).accept(data)  # the keyless decoder too


def _sealed_state(session):
    return encode(STATE, 1, session.last_sent + 1, np.ones((3, 6)), link=session)
