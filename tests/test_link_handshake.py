"""The handshake strangers cannot spend (budgets per source, MAC1 before anything, one PROOF per challenge tied to its
source, REFUSED only from the bridge and naming the host's HELLO, no answer bigger than its request, no key id to
anyone), its forward secrecy, and re-keying a running session without a gap in its stream: in process, on the
gate's own clock (deterministic), and over loopback where the address is what is tested."""

import socket
import struct
import threading
import time

import numpy as np
import pytest

from rehabkit.hardware.link.bridge_end import BridgeLink
from rehabkit.hardware.link.clock import wait_readable
from rehabkit.hardware.link.host_end import HostLink
from rehabkit.hardware.link.protocol import COMMAND, HEADER, PLAIN, STATE, Receiver, encode, pack_bytes
from rehabkit.hardware.security.gate import ANSWERS_PER_S, BridgeGate
from rehabkit.hardware.security.handshake import (
    CHALLENGE,
    HELLO,
    KEY_NEEDED,
    NO_KEY,
    OTHER_KEY,
    PROOF,
    REFUSED,
    WELCOME,
    HostHandshake,
    handshake,
    peek_kind,
    refused,
)
from rehabkit.hardware.security.keys import new_key
from rehabkit.hardware.security.session import session_for
from tests.test_link_security import HOST, _shake

STRANGER = ("127.0.0.1", 9999)


@pytest.fixture(scope="module")
def key(tmp_path_factory):
    return new_key("hit-1", tmp_path_factory.mktemp("keys") / "hit-1.key")


def _junk_hello(i: int) -> bytes:
    return PLAIN.seal(pack_bytes(HELLO, 1, i, bytes(64)))  # (a HELLO's size, a MAC1 only a key holder could make)


def test_a_junk_flood_spends_its_own_budget_and_every_handshake_goes_through(key):
    """The review's attack: 100 junk datagrams a second from another port (HELLOs without MAC1, commands without the
    key) stopped 6 of 6 handshakes. Now the stranger gets at most its own budget of refusals, and each of 6 hosts,
    one a second among the junk, opens its session; so does one after a flood from 1000 ports."""
    gate = BridgeGate(key, 1)
    answered, sessions = 0, []
    for second in range(6):
        for i in range(100):
            now = second + i / 100
            for data in (_junk_hello(i), encode(COMMAND, 1, i, np.zeros(6))):
                reply = gate.reply(data, STRANGER, now)[0] if peek_kind(data) == HELLO else \
                    gate.refuse_unauthenticated(data, STRANGER, now)
                answered += reply is not None
                assert reply is None or peek_kind(reply) == REFUSED and len(reply) <= len(data)
            if i == 50:  # a host, from a port of its own (the last one's session no longer live: a second silent)
                sessions.append(_shake(key, gate, addr=("127.0.0.1", 41000 + second), now=now)[0])
    assert answered <= ANSWERS_PER_S * (1 + 6)  # (a full budget, then its rate: 5 a second, of 1200 datagrams)
    assert all(s is not None for s in sessions) and len({s.id for s in sessions}) == 6
    for port in range(1000):  # a stranger from many ports: each spends its own; the budgets kept are bounded
        gate.reply(_junk_hello(port), ("127.0.0.1", 20000 + port), 10.0)
    assert _shake(key, gate, addr=("127.0.0.1", 42000), now=10.0)[0] is not None


def test_only_a_key_holders_hello_gets_a_challenge_and_no_answer_is_bigger_or_names_a_key(key, tmp_path):
    other = new_key("hit-1", tmp_path / "other.key")
    gate = BridgeGate(key, 1)
    exchanged = []

    def ask(data: bytes, addr=HOST):
        reply, why = gate.reply(data, addr, 0.0)
        exchanged.append((data, reply))
        return reply, why

    reply, why = ask(HostHandshake(other, 1).next(1))
    assert why == "other-key" and refused(reply, 1)[0] == OTHER_KEY and gate.challenges == 0  # no state kept
    host = HostHandshake(key, 1)
    challenge, why = ask(host.next(2))
    assert why == "" and peek_kind(challenge) == CHALLENGE and gate.challenges == 1
    assert host.take(challenge) is None and host.pending is not None
    welcome, _ = ask(host.next(3))
    assert peek_kind(welcome) == WELCOME and host.take(welcome) is not None
    keyless = BridgeGate(None, 1)
    reply, why = keyless.reply(host.next(4), HOST, 0.0)
    exchanged.append((host.next(5), reply))
    assert why == "no-key" and refused(reply, 1)[0] == NO_KEY
    command = encode(COMMAND, 1, 9, np.zeros(6))
    exchanged.append((command, gate.refuse_unauthenticated(command, STRANGER, 0.0)))
    assert refused(exchanged[-1][1], 1)[0] == KEY_NEEDED
    short = PLAIN.seal(pack_bytes(COMMAND, 1, 10, b""))  # (smaller than a REFUSED: not answered at all)
    assert gate.refuse_unauthenticated(short, ("127.0.0.1", 9998), 0.0) is None
    sizes = [(len(a), len(b)) for a, b in exchanged]
    assert sizes == [(110, 55), (110, 110), (110, 58), (110, 55), (94, 55)]  # never bigger than what they answer
    for _, answer in exchanged:
        assert bytes.fromhex(key.id) not in answer and bytes.fromhex(other.id) not in answer


def test_a_challenge_takes_one_proof_from_its_hellos_source_and_a_replayed_hello_makes_nothing(key):
    gate = BridgeGate(key, 1)
    host = HostHandshake(key, 1)
    hello = host.next(1)
    host.take(gate.reply(hello, HOST, 0.0)[0])
    proof = host.next(2)
    assert gate.reply(hello, STRANGER, 0.0) == (None, "other-address")  # the same HELLO from elsewhere: nothing
    assert gate.reply(proof, STRANGER, 0.0) == (None, "other-address")  # refused before anything is computed
    wrong = PLAIN.seal(pack_bytes(PROOF, 1, 3, host.eh + bytes(32)))
    # the review's wrong-PROOF flood: one is tried (and spends the challenge), the rest find none, at a lookup each
    reasons = [gate.reply(wrong, HOST, 0.0)[1] for _ in range(1000)]
    assert reasons == ["bad-proof"] + ["stale-proof"] * 999
    assert gate.reply(proof, HOST, 0.0) == (None, "stale-proof") and gate.session is None
    session, _ = _shake(key, gate)  # (the host starts afresh: new ephemeral keys)
    assert session is not None and gate.challenges == 0
    assert gate.reply(hello, HOST, 0.0) == (None, "replayed-hello")  # spent: answered never again


def test_the_host_takes_a_refused_only_from_the_bridge_and_naming_its_hello(key):
    """A forged REFUSED aborted the host's handshake: one datagram from 127.0.0.2. Now one naming another HELLO is
    ignored, and one from another address is not read as the bridge's, even naming this HELLO (an on-path forger's):
    the handshake goes on to its session."""
    host = HostHandshake(key, 1)
    other = PLAIN.seal(pack_bytes(REFUSED, 1, 1, bytes([NO_KEY]) + bytes(8)))
    assert host.take(other) is None and host.refusal is None
    bridge, forger, sock = (socket.socket(socket.AF_INET, socket.SOCK_DGRAM) for _ in range(3))
    bridge.bind(("127.0.0.1", 0))
    forger.bind(("127.0.0.2", 0))
    gate = BridgeGate(key, 1)

    def serve():  # the bridge: the forger answers each HELLO first, naming it; then the gate answers
        while wait_readable(bridge, 2.0):
            data, addr = bridge.recvfrom(65536)
            if peek_kind(data) == HELLO:
                eh = data[HEADER.size:HEADER.size + 8]
                forger.sendto(PLAIN.seal(pack_bytes(REFUSED, 1, 1, bytes([NO_KEY]) + eh)), addr)
            reply, _ = gate.reply(data, addr)
            if reply is not None:
                bridge.sendto(reply, addr)
            if gate.session is not None:
                return

    answering = threading.Thread(target=serve)
    answering.start()
    seq = iter(range(1, 1000))
    try:
        session = handshake(sock, bridge.getsockname(), key, 1, lambda: next(seq), timeout=2.0)
    finally:
        answering.join()
        for s in (bridge, forger, sock):
            s.close()
    assert session.id == gate.session.id


def test_a_captured_session_is_not_opened_by_the_key_alone(key):
    """Forward secrecy: the key file of a retired computer and a capture of a whole session (its handshake, a state of
    the person's joints) open nothing; only the two ends, with the X25519 exchange they dropped, could. A re-keyed
    session's keys open neither the one before it nor after."""
    from cryptography.exceptions import InvalidTag
    from cryptography.hazmat.primitives import hashes
    from cryptography.hazmat.primitives.ciphers.aead import ChaCha20Poly1305
    from cryptography.hazmat.primitives.kdf.hkdf import HKDF

    gate = BridgeGate(key, 1)
    host = HostHandshake(key, 1)
    hello = host.next(1)
    challenge, _ = gate.reply(hello, HOST, 0.0)
    host.take(challenge)
    session = host.take(gate.reply(host.next(2), HOST, 0.0)[0])
    joints = np.radians([10.0, 20.0, 30.0, 40.0, 50.0, 60.0]) * np.ones((3, 6))
    state = encode(STATE, 1, 7, joints, sent_at=1.0, link=gate.session)
    assert Receiver(STATE, 1, 6).take(session.open(state)[0]).values.tolist() == joints.tolist()  # the ends can
    eh, eb = hello[HEADER.size:HEADER.size + 32], challenge[HEADER.size:HEADER.size + 32]
    for guess in (b"", bytes(32), eh, eb):  # what the thief can put where the exchange's result went
        thief, bridge_proof, _ = session_for(key, 1, eh, eb, guess, host=True)
        thief.id = session.id  # (as the capture says)
        assert thief.open(state) == (None, "authentication") and bridge_proof not in challenge
    info = b"rehabkit link v7 session" + struct.pack("<I", 1) + bytes.fromhex(key.id)
    old = HKDF(algorithm=hashes.SHA256(), length=64, salt=eh + eb, info=info).derive(key.secret)
    with pytest.raises(InvalidTag):  # (the last version's keys: the key and the public values alone)
        ChaCha20Poly1305(old[32:]).decrypt(struct.pack("<Q", 7) + bytes(4), state[HEADER.size:], state[:HEADER.size])
    again = HostHandshake(key, 1)  # re-keyed: the same host, a new exchange
    again.take(gate.reply(again.next(3), HOST, 0.0)[0])
    rekeyed = again.take(gate.reply(again.next(4), HOST, 0.0)[0])
    later = encode(STATE, 1, 8, joints, sent_at=1.0, link=gate.session)
    assert gate.rekeys == 1 and rekeyed.id != session.id
    assert session.open(later)[1] == "other-session" and rekeyed.open(state)[1] == "other-session"


def test_a_session_rekeys_on_schedule_without_a_gap_in_its_stream(key):
    """The host re-keys every 50 ms of the link's time, alongside a 1 kHz stream of commands and states over
    loopback: every command reaches the bridge and every state the host, in order, none refused, across 19 new
    sessions."""
    bridge = BridgeLink(1, 6, key=key)
    host = HostLink("127.0.0.1", bridge.port, 1, key, Receiver(STATE, 1, 6), 0.001, rekey_s=0.05)
    def answer():  # (the handshake's answers, until the session is made)
        while bridge.gate.session is None:
            bridge.gather(time.monotonic() + 0.05)

    answering = threading.Thread(target=answer)
    answering.start()
    host.open_session()
    answering.join()
    rx, commands, states = Receiver(COMMAND, 1, 6), [], []
    for i in range(1000):
        host.send(COMMAND, np.full(6, float(i)), i * 1e-3)
        got = []
        while not got and wait_readable([bridge.sock, bridge.session_sock], 1.0):
            got = bridge.arrived()
        commands += [rx.take(plain).values[0] for plain, _ in got]
        bridge.send((STATE, np.full((3, 6), float(i)), i * 1e-3, 0.0, 0, 0, None, None), bridge.gate.peer)
        came = []
        while not came and wait_readable(host.sock, 1.0):
            came = host.arrived(time.monotonic, False)
        states += [host.rx.take(plain).values[0, 0] for plain, _ in came]
    host.close()
    assert commands == states == list(range(1000))
    assert host.rekeys == bridge.gate.rekeys == 19 and len(bridge.sessions) == 1
    assert dict(host.rx.dropped) == {} and set(bridge.rx.dropped) <= {"handshake-hello-again"}
    bridge.close()
