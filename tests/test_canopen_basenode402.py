"""A simulated drive driven by a master that is not rehabkit's: canopen's own ``BaseNode402`` through its documented
API, as a lab's Python script would — in real time on a python-can virtual bus with a SYNC producer (BaseNode402 waits
on the wall clock for each state, reading the statusword from a TPDO it finds mapped). Asserted: what holds however
loaded the machine is."""

import itertools
import os
import time

import canopen
import pytest
from canopen.profiles.p402 import BaseNode402

from rehabkit.canopen.config import DriveUnits
from rehabkit.canopen.simulated.drive import EDS, SimulatedDrive

CHANNEL = itertools.count()


class Joint:
    """A free inertia (0.01 kg·m²), integrated over each SYNC's cycle (10 ms) with the torque it is given."""

    def __init__(self) -> None:
        self.q = self.qd = self.tau = 0.0

    def apply(self, torque: float) -> None:
        self.tau = torque
        self.qd += torque / 0.01 * 0.01
        self.q += self.qd * 0.01

    def read(self) -> tuple[float, float, float]:
        return self.q, self.qd, self.tau


@pytest.fixture
def lab():
    channel = f"rehabkit-basenode402-{os.getpid()}-{next(CHANNEL)}"
    master, drives = canopen.Network(), canopen.Network()
    for net in (master, drives):
        net.NOTIFIER_CYCLE = 0.05  # (its reader's wait for a frame: what disconnecting it waits for, 1 s by default)
        net.connect(interface="virtual", channel=channel, receive_own_messages=False)
    node = BaseNode402(1, str(EDS))
    master.add_node(node)
    offset = [0.0]  # (the drive's watchdog clock: the wall clock, moved on at the end)
    joint = Joint()
    drive = SimulatedDrive(drives, 1, joint, DriveUnits(counts_per_rad=1000.0, rated_torque_nm=1.0),
                           now=lambda: time.monotonic() + offset[0])
    yield master, node, drive, joint, offset
    master.sync.stop()
    for net in (master, drives):
        net.disconnect()


def test_basenode402_enables_a_simulated_drive_runs_cst_and_csp_and_leaves_it_quiet(lab):
    master, node, drive, joint, offset = lab
    node.nmt.state = "PRE-OPERATIONAL"
    node.sdo[0x1006].raw = 10_000  # [µs] the SYNC's period
    node.sdo[0x1016][1].raw = 0x7F << 16 | 500  # (the drive watches the master's heartbeat)
    node.tpdo.read()
    node.rpdo.read()
    tx, rx = node.tpdo[1], node.rpdo[1]
    tx.clear()
    tx.add_variable(0x6041)  # (BaseNode402 reads the statusword, and the mode display, from TPDOs)
    tx.add_variable(0x6061)
    tx.add_variable(0x6064)
    tx.trans_type, tx.enabled = 1, True
    rx.clear()
    rx.add_variable(0x6040)
    rx.add_variable(0x6071)
    rx.trans_type, rx.enabled = 255, True  # (event-driven: BaseNode402 sends it as it sets the controlword)
    node.tpdo.save()
    node.rpdo.save()
    node.setup_402_state_machine()
    node.nmt.state = "OPERATIONAL"
    beat = master.send_periodic(0x77F, [0x05], 0.05)
    master.sync.start(0.01)
    try:
        node.op_mode = "CYCLIC SYNCHRONOUS TORQUE"
        assert node.op_mode == "CYCLIC SYNCHRONOUS TORQUE"
        node.state = "OPERATION ENABLED"
        assert node.state == "OPERATION ENABLED"
        rx["Target torque"].raw = 100  # 10 % of the rated torque, forward
        rx.transmit()
        start = node.sdo[0x6064].raw
        for _ in range(5):
            tx.wait_for_reception(1.0)
        assert node.sdo[0x6064].raw > start and joint.qd > 0
        rx["Target torque"].raw = 0
        rx.transmit()
        node.op_mode = "CYCLIC SYNCHRONOUS POSITION"
        assert node.op_mode == "CYCLIC SYNCHRONOUS POSITION"
        here = node.sdo[0x6064].raw
        node.sdo[0x607A].raw = here - 2000  # (a position target behind it: it goes back)
        for _ in range(10):
            tx.wait_for_reception(1.0)
        assert node.sdo[0x6064].raw < here
        node.state = "SWITCH ON DISABLED"  # the end: power stage off, pre-operational, heartbeat and SYNC stop
        node.sdo[0x1016][1].raw = 0
        node.nmt.state = "PRE-OPERATIONAL"
        assert node.sdo[0x1000].raw  # (answered after the drive took the NMT command: frames are taken in order)
    finally:
        master.sync.stop()
        beat.stop()
    assert node.state == "SWITCH ON DISABLED" and drive.nmt.state == "PRE-OPERATIONAL"
    offset[0] += 60.0  # a minute later on the drive's clock
    drive.poll()
    assert drive.emcy_sent == [] and [e.code for e in node.emcy.log] == []
