"""A deterministic bench for the CiA 301/402 conformance tests: one simulated drive and a canopen master on a
lock-step channel (every frame delivered as it is sent, in this thread, in order: an SDO's answer is there when the
client looks for it, a SYNC's TPDOs once it is sent), every frame recorded, the drive's watchdogs on a clock the
test moves."""

from __future__ import annotations

import struct
from pathlib import Path

import canopen

from rehabkit.canopen.bus.drive_dictionary import object_dictionary
from rehabkit.canopen.bus.lockstep_channel import LockstepChannel
from rehabkit.canopen.config import DriveUnits
from rehabkit.canopen.simulated.drive import EDS, SimulatedDrive

DATA = Path(__file__).resolve().parent / "data" / "canopen_eds"
FILES = sorted(p for p in DATA.iterdir() if p.suffix in (".eds", ".dcf")) + [EDS]
NODE = 1  # (the maxon DCF is node 1's)
MASTER = 0x7F


class Joint:
    """A joint at rest that records the torques it is given."""

    def __init__(self) -> None:
        self.applied: list[float] = []

    def apply(self, torque: float) -> None:
        self.applied.append(torque)

    def read(self) -> tuple[float, float, float]:
        return 0.0, 0.0, self.applied[-1] if self.applied else 0.0


class _Pumped(canopen.Network):
    def send_message(self, can_id: int, data: bytes, remote: bool = False) -> None:
        super().send_message(can_id, data, remote)
        self.bench.pump()


class Bench:
    """The drive serving ``eds`` (node 1) and its master; ``t``: the drive's watchdogs' clock [s]."""

    def __init__(self, eds: Path = EDS, units: DriveUnits | None = None):
        channel = LockstepChannel("conformance")
        self.t = 0.0
        self.frames: list[tuple[int, bytes]] = []
        self._tap, self._drive_end = channel.end(), channel.end()
        self.master = _Pumped(channel.end())
        self.master.bench = self
        self._drives = canopen.Network(self._drive_end)
        self.joint = Joint()
        self.drive = SimulatedDrive(self._drives, NODE, self.joint, units or DriveUnits(), eds=eds, clocked=True,
                                    now=lambda: self.t)
        # canopen's master node with the file's dictionary as canopen parses it, the parse made once per file (as the
        # drive's own is): a parse per bench was 7 of the conformance suite's 8 s of CPU (nanotec's file: 64 ms)
        self.remote = canopen.RemoteNode(NODE, object_dictionary(eds, NODE))
        self.master.add_node(self.remote)
        self.pump()

    def pump(self) -> None:
        while self._drive_end.inbox or self._tap.inbox or self.master.bus.inbox:
            self._drive_end.deliver(self._drives)
            self.frames.extend((m.arbitration_id, bytes(m.data)) for m in self._tap.frames())
            self.master.bus.deliver(self.master)

    def sent(self, cob: int) -> list[bytes]:
        """The data of every frame with COB-ID ``cob`` so far (the drive's own, sent by itself, delivered first)."""
        self.pump()
        return [d for c, d in self.frames if c == cob]

    def emcys(self) -> list[tuple[int, int]]:
        """(error code, error register) of every EMCY the drive sent."""
        return [(int.from_bytes(d[:2], "little"), d[2]) for d in self.sent(0x80 + NODE)]

    # -- the master's side, raw (vendor objects need no EDS entry of the master's) -------------------------

    def write(self, index: int, sub: int, fmt: str, value: int) -> None:
        self.remote.sdo.download(index, sub, struct.pack(fmt, value))

    def read(self, index: int, sub: int, fmt: str) -> int:
        return struct.unpack(fmt, self.remote.sdo.upload(index, sub)[: struct.calcsize(fmt)])[0]

    def abort(self, call, *args) -> int | None:
        """The SDO abort code ``call`` ends with (None: it did not abort)."""
        try:
            call(*args)
        except canopen.SdoAbortedError as exc:
            return exc.code
        return None

    def nmt(self, command: int) -> None:
        self.master.send_message(0x000, bytes([command, NODE]))

    def sync(self, n: int = 1) -> None:
        for _ in range(n):
            self.master.send_message(0x80, b"")

    def heartbeat(self) -> None:
        self.master.send_message(0x700 + MASTER, b"\x05")

    def statusword(self) -> int:
        return self.read(0x6041, 0, "<H")

    def map_pdo(self, comm: int, entries: list[int], trans_type: int = 1) -> int:
        """PDO ``comm`` (0x1400.. or 0x1800..) mapped to ``entries`` as CiA 301 has a master do it (invalid,
        entries, valid); its COB-ID."""
        cob = self.read(comm, 1, "<I") & ~0x80000000
        self.write(comm, 1, "<I", cob | 0x80000000)
        self.write(comm, 2, "<B", trans_type)
        self.write(comm + 0x200, 0, "<B", 0)
        for k, entry in enumerate(entries, start=1):
            self.write(comm + 0x200, k, "<I", entry)
        self.write(comm + 0x200, 0, "<B", len(entries))
        self.write(comm, 1, "<I", cob)
        return cob & 0x7FF
