"""Link keys: one secret per robot (``<robot>-<robot id>``, as its e-stop latch is named), kept in a small text file
readable by its owner only, the same file at the host and at the bridge (``rehabkit keys new hit-1``).

The file says which robot the key is for and its key id (the first 8 bytes of a SHA-256 of the secret: safe to
show, to log and to compare, it names the key without revealing it); the secret itself is never printed, logged
or written anywhere else. A key file is checked as ``ssh``'s StrictModes checks a private key (:func:`load_key`); a
new one is written whole (temp, rename, the folder synced), its folder made owner-only if new.
"""

from __future__ import annotations

import base64
import errno
import hashlib
import os
import re
import secrets
import stat
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path

from rehabkit.core.io import atomic_write_text

KEY_BYTES = 32
_ROBOT_RE = re.compile(r"^[a-z0-9][a-z0-9_.-]*-[0-9]+$")
HEADLINE = "# rehabkit link key: secret. Keep it owner-only (chmod 600); the same file at the host and at the bridge."


class KeyFileError(ValueError):
    """A key file that cannot be used: ``path``, what is wrong (``problem``) and how to put it right (``fix``);
    ``kind``: what is wrong as a code (``symlink``, ``owner``, …; empty where none is given), ``owner``: the user
    who owns the file where that is what is wrong (``kind == "owner"``)."""

    def __init__(self, path: str | Path, problem: str, fix: str, kind: str = "", owner: int | None = None):
        self.path, self.problem, self.fix = str(path), problem, fix
        self.kind, self.owner = kind, owner  # (the problem as fields: tests and callers need not read its words)
        super().__init__(f"key file {path}: {problem}; {fix}")


def key_id(secret: bytes) -> str:
    """The key's public name: 16 hex digits of a SHA-256 of the secret."""
    return hashlib.sha256(b"rehabkit link key id\0" + secret).hexdigest()[:16]


@dataclass(frozen=True)
class LinkKey:
    """A robot's link key: ``robot`` (``hit-1``), the secret (never shown) and where it was read from."""

    robot: str
    secret: bytes = field(repr=False)
    path: Path | None = None

    @property
    def id(self) -> str:
        return key_id(self.secret)

    def __repr__(self) -> str:
        return f"LinkKey({self.robot!r}, id={self.id}, path={str(self.path)!r})"

    def __str__(self) -> str:
        return f"key {self.id} for {self.robot}" + (f" ({self.path})" if self.path else "")


def default_key_path(robot: str) -> Path:
    """Where ``rehabkit keys new ROBOT`` writes by default: ``$REHABKIT_STATE/keys/ROBOT.key``."""
    from rehabkit.core.safety.estop import state_dir

    return state_dir() / "keys" / f"{robot}.key"


def new_key(robot: str, out: str | Path, replace: bool = False) -> LinkKey:
    """A fresh key for ``robot`` written to ``out`` whole (temp, then rename), readable by its owner only;
    an existing file is kept unless ``replace`` (rotating a key is a deliberate act)."""
    if not _ROBOT_RE.match(robot):
        raise KeyFileError(out, f"'{robot}' is not a robot's link name", "name it ROBOT-ID as its e-stop latch is "
                           "named, e.g. hit-1 (robot hit, robot_id 1)")
    out = Path(out)
    if out.is_symlink():
        raise KeyFileError(out, "a symbolic link", "write the key to a file of its own (a link could point anywhere)",
                           kind="symlink")
    if out.exists() and not replace:
        raise KeyFileError(out, "exists", "pass --replace to rotate the key (then give the new file to both ends)")
    out.parent.mkdir(mode=0o700, parents=True, exist_ok=True)  # (a keys/ folder made here: its owner's only)
    key = LinkKey(robot, secrets.token_bytes(KEY_BYTES), out)
    text = (f"{HEADLINE}\nrobot: {robot}\nid: {key.id}\ncreated: {datetime.now(UTC).isoformat(timespec='seconds')}\n"
            f"secret: {base64.urlsafe_b64encode(key.secret).decode()}\n")
    atomic_write_text(out, text, private=True)
    folder = os.open(out.parent, os.O_RDONLY | os.O_DIRECTORY)
    try:
        os.fsync(folder)  # (the rename itself on disk: a power cut leaves the old key or the new, never none)
    finally:
        os.close(folder)
    return key


def load_key(path: str | Path) -> LinkKey:
    """The key in ``path``, checked as ``ssh``'s StrictModes checks a private key: refused (:class:`KeyFileError`)
    when missing, a symbolic link, not this user's (or root's), readable by others, in a folder that is not this
    user's (or root's) or that others may write (they could swap the key), or malformed."""
    path = Path(path).expanduser()
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NOFOLLOW)
    except FileNotFoundError:
        raise KeyFileError(path, "no such file", "make one with `rehabkit keys new ROBOT-ID --out FILE` and give "
                           "the same file to the bridge") from None
    except OSError as exc:
        if exc.errno == errno.ELOOP:
            raise KeyFileError(path, "a symbolic link", "name the key file itself (a link could be pointed "
                               "elsewhere)", kind="symlink") from None
        raise KeyFileError(path, f"cannot be read ({exc.strerror})", "check the path") from None
    with os.fdopen(fd, errors="replace") as f:
        _strict(path, os.fstat(f.fileno()))
        text = f.read()
    fields = {}
    for line in text.splitlines():
        name, sep, value = line.partition(":")
        if sep and not line.startswith("#"):
            fields[name.strip()] = value.strip()
    try:
        secret = base64.urlsafe_b64decode(fields["secret"].encode())
        robot = fields["robot"]
    except (KeyError, ValueError):
        raise KeyFileError(path, "not a rehabkit link key (no robot or secret line)",
                           "make one with `rehabkit keys new ROBOT-ID`") from None
    if len(secret) != KEY_BYTES:
        raise KeyFileError(path, f"its secret is {len(secret)} bytes, not {KEY_BYTES}", "make a new key")
    key = LinkKey(robot, secret, path)
    if fields.get("id", key.id) != key.id:
        raise KeyFileError(path, f"its id line says {fields['id']} but the secret's id is {key.id} (edited?)",
                           "make a new key")
    return key


def _strict(path: Path, st: os.stat_result) -> None:
    """The file's and its folder's owner and modes, as StrictModes checks them."""
    me = os.geteuid()
    if not stat.S_ISREG(st.st_mode):
        raise KeyFileError(path, "not a file", "name the key file itself")
    if st.st_uid not in (me, 0):
        raise KeyFileError(path, f"owned by user {st.st_uid}, not this one ({me})",
                           "make this user's own key (`rehabkit keys new ROBOT-ID`), or chown it", kind="owner",
                           owner=st.st_uid)
    if st.st_mode & 0o077:
        raise KeyFileError(path, f"readable by others (mode {stat.S_IMODE(st.st_mode):o})", f"chmod 600 {path}")
    folder = path.absolute().parent
    fst = os.stat(folder)
    if fst.st_uid not in (me, 0):
        raise KeyFileError(path, f"its folder {folder} is owned by user {fst.st_uid}, not this one ({me}): its owner "
                           "could swap the key", "keep keys in a folder of this user's own (chmod 700)")
    if fst.st_mode & 0o022:
        raise KeyFileError(path, f"its folder {folder} may be written by others (mode {stat.S_IMODE(fst.st_mode):o}): "
                           "they could swap the key", f"chmod go-w {folder}")


def check_robot(key: LinkKey, robot: str) -> None:
    """Refuse a key made for another robot than ``robot`` (``hit-1``)."""
    if key.robot != robot:
        raise KeyFileError(key.path or "?", f"the key is for robot {key.robot}, this link is {robot}",
                           f"use {robot}'s key (`rehabkit keys new {robot}` makes one)")
