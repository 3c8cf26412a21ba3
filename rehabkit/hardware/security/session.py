"""An authenticated session's cryptography: its keys from the robot's key and both ends' nonces, its datagrams sealed
with ChaCha20-Poly1305 (the ``cryptography`` package) and an IPsec-style anti-replay window.

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

NONCE, MAC, KEY_ID = 16, 32, 8  # a handshake nonce, an HMAC-SHA256, a key id [bytes]
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


def proof(key: LinkKey, who: bytes, robot: int, nh: bytes, nb: bytes) -> bytes:
    return hmac.digest(key.secret, who + struct.pack("<I", robot) + bytes.fromhex(key.id) + nh + nb, "sha256")


def session_for(key: LinkKey, robot: int, nh: bytes, nb: bytes, host: bool) -> Session:
    """The session both ends derive from the key and both nonces (``host``: the host's end of it)."""
    from cryptography.hazmat.primitives import hashes
    from cryptography.hazmat.primitives.kdf.hkdf import HKDF

    info = b"rehabkit link v%d session" % VERSION + struct.pack("<I", robot) + bytes.fromhex(key.id)
    keys = HKDF(algorithm=hashes.SHA256(), length=64, salt=nh + nb, info=info).derive(key.secret)
    sid = int.from_bytes(hmac.digest(key.secret, b"session id" + nh + nb, "sha256")[:4], "little") | 1
    to_bridge, to_host = keys[:32], keys[32:]
    return Session(sid, key.id, *((to_bridge, to_host) if host else (to_host, to_bridge)))


