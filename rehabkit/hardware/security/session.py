"""An authenticated session's cryptography: its keys from the robot's key and an ephemeral X25519 exchange (forward
secret), its datagrams sealed with ChaCha20-Poly1305 (all from the ``cryptography`` package) and an IPsec-style
anti-replay window.

A datagram is sealed with its body encrypted (a person's joint angles and forces are health data) and header and
body authenticated; its nonce is the sequence number, which the sender never repeats in a session (one key per
direction, per session). The receiver keeps the highest sequence number seen and a bitmap of the 64 before it
(RFC 4303 §3.4.3) and opens a datagram only if its tag holds and its number was not seen; the window moves only for
an authentic datagram. The handshake that makes a session: :mod:`rehabkit.hardware.security.handshake`.
"""

from __future__ import annotations

import hmac
import struct

from rehabkit.hardware.link.protocol import HEADER, SEQ, SEQ_AT, SESSION_AT, VERSION
from rehabkit.hardware.security.keys import LinkKey

PUBLIC, MAC, MAC1, KEY_ID = 32, 32, 16, 8  # an X25519 public key, an HMAC-SHA256, a HELLO's MAC1, a key id [bytes]
TAG = 16  # Poly1305's
WINDOW = 64  # sequence numbers the anti-replay window remembers behind the highest


class ReplayWindow:
    """Sequence numbers seen, as IPsec's receiver keeps them: the highest, and a bitmap of the 64 before it."""

    def __init__(self) -> None:
        self.top, self.bits = 0, 0

    def fresh(self, seq: int) -> bool:
        """Not seen, and not older than the window (check before the tag, mark after it holds)."""
        if seq > self.top:
            return True
        back = self.top - seq
        return back < WINDOW and not self.bits >> back & 1 and seq > 0

    def mark(self, seq: int) -> None:
        if seq > self.top:
            shift = seq - self.top
            self.bits = (self.bits << shift | 1) & (1 << WINDOW) - 1 if shift < WINDOW else 1
            self.top = seq
        else:
            self.bits |= 1 << (self.top - seq)


class Session:
    """One authenticated session's end: seals what it sends, opens what it receives (see the module's doc)."""

    def __init__(self, sid: int, key_id: str, send_key: bytes, receive_key: bytes):
        from cryptography.exceptions import InvalidTag  # (only a keyed link pays for importing it)
        from cryptography.hazmat.primitives.ciphers.aead import ChaCha20Poly1305

        self.id, self.key_id = sid, key_id
        self.right = "drive"  # what the session may do: "drive" (the robot's key), or "clear" (a clearing key's)
        self._seal, self._open = ChaCha20Poly1305(send_key), ChaCha20Poly1305(receive_key)
        self._invalid = InvalidTag
        self.window = ReplayWindow()
        self.last_sent = 0

    def seal(self, plain: bytes) -> bytes:
        """Header and body (the header naming this session) → the datagram: body encrypted, both authenticated."""
        seq = SEQ.unpack_from(plain, SEQ_AT)[0]
        if seq <= self.last_sent:  # a repeated nonce would give the key away: never, whatever the caller does
            raise ValueError(f"sequence number {seq} after {self.last_sent}: a session never repeats one")
        self.last_sent = seq
        return plain[:HEADER.size] + self._seal.encrypt(_nonce(seq), plain[HEADER.size:], plain[:HEADER.size])

    def open(self, data: bytes) -> tuple[bytes | None, str]:
        """Header and body of an authentic datagram of this session not seen before, or None and why not."""
        if len(data) < HEADER.size:
            return None, "length"
        sid = SEQ.unpack_from(data, SESSION_AT)[0]
        if sid != self.id:
            return None, "unauthenticated" if sid == 0 else "other-session"
        if len(data) < HEADER.size + TAG:
            return None, "length"
        seq = SEQ.unpack_from(data, SEQ_AT)[0]
        if not self.window.fresh(seq):
            return None, "replayed"
        head = data[:HEADER.size]
        try:
            body = self._open.decrypt(_nonce(seq), data[HEADER.size:], head)
        except self._invalid:
            return None, "authentication"
        self.window.mark(seq)
        return head + body, ""


def _nonce(seq: int) -> bytes:
    return struct.pack("<Q", seq) + b"\0\0\0\0"


def mac1_key(key: LinkKey) -> bytes:
    """The key of a HELLO's MAC1 (the check any key holder passes, and no one else: made once per key)."""
    return hmac.digest(key.secret, b"rehabkit link mac1", "sha256")


def mac1(mac_key: bytes, plain: bytes) -> bytes:
    return hmac.digest(mac_key, plain, "sha256")[:MAC1]


def session_for(key: LinkKey, robot: int, eh: bytes, eb: bytes, dh: bytes, host: bool) -> tuple[Session, bytes, bytes]:
    """The session both ends derive from the robot's key, both ephemeral X25519 public keys (``eh`` the host's,
    ``eb`` the bridge's) and their Diffie-Hellman result ``dh`` (``host``: the host's end of it), and the two
    proofs of the handshake (the bridge's, the host's). Without ``dh`` — which no one keeps once the session is
    made — the robot's key alone opens nothing captured: the sessions are forward secret."""
    from cryptography.hazmat.primitives import hashes
    from cryptography.hazmat.primitives.kdf.hkdf import HKDF

    info = b"rehabkit link v%d session" % VERSION + struct.pack("<I", robot) + bytes.fromhex(key.id)
    okm = HKDF(algorithm=hashes.SHA256(), length=3 * 32 + 4, salt=eh + eb, info=info).derive(key.secret + dh)
    to_bridge, to_host, confirm = okm[:32], okm[32:64], okm[64:96]
    sid = int.from_bytes(okm[96:], "little") | 1
    session = Session(sid, key.id, *((to_bridge, to_host) if host else (to_host, to_bridge)))
    return session, hmac.digest(confirm, b"bridge", "sha256"), hmac.digest(confirm, b"host", "sha256")


def ephemeral() -> tuple[object, bytes]:
    """A fresh X25519 key pair: the private key (used once, then dropped) and its public bytes."""
    from cryptography.hazmat.primitives.asymmetric.x25519 import X25519PrivateKey

    private = X25519PrivateKey.generate()
    return private, private.public_key().public_bytes_raw()


def exchange(private, public: bytes) -> bytes | None:
    """X25519 of our ``private`` key with the peer's ``public`` bytes, or None if they are no usable key (a
    low-order point: a forger's)."""
    from cryptography.hazmat.primitives.asymmetric.x25519 import X25519PublicKey

    try:
        return private.exchange(X25519PublicKey.from_public_bytes(public))
    except ValueError:
        return None


def warm_up(key: LinkKey, robot: int) -> None:
    """A handshake's cryptography done once and a datagram sealed and opened, then forgotten: the libraries' first
    use (imports, their tables) costs milliseconds, which a real-time loop must not spend in its first handshake."""
    from rehabkit.hardware.link.protocol import pack_bytes

    (a, pa), (b, pb) = ephemeral(), ephemeral()
    host, _, _ = session_for(key, robot, pa, pb, exchange(a, pb), host=True)
    bridge, _, _ = session_for(key, robot, pa, pb, exchange(b, pa), host=False)
    bridge.open(host.seal(pack_bytes(0, robot, 1, bytes(8), host.id)))
