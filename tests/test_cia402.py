"""The CiA 402 drive state machine against the profile's transition table (IEC 61800-7-201, figure "state machine")."""

from pathlib import Path

import pytest

from rehabkit.canopen.cia402 import (
    DISABLE_OPERATION,
    DISABLE_VOLTAGE,
    ENABLE_OPERATION_CMD,
    FAULT_RESET,
    QUICK_STOP_CMD,
    SHUTDOWN,
    SWITCH_ON_CMD,
    VOLTAGE_ENABLED,
    Drive402,
    State,
    command,
)

S = State


def _at(state: State, option: int = 2) -> Drive402:
    """A drive brought to ``state`` the way a master brings it there."""
    d = Drive402(quick_stop_option=option)
    path = {S.SWITCH_ON_DISABLED: [], S.READY_TO_SWITCH_ON: [SHUTDOWN], S.SWITCHED_ON: [SHUTDOWN, SWITCH_ON_CMD],
            S.OPERATION_ENABLED: [SHUTDOWN, SWITCH_ON_CMD, ENABLE_OPERATION_CMD],
            S.QUICK_STOP_ACTIVE: [SHUTDOWN, SWITCH_ON_CMD, ENABLE_OPERATION_CMD, QUICK_STOP_CMD]}[state]
    for cw in path:
        d.write(cw)
    assert d.state is state
    return d


# (from, controlword, to, the profile's transition number)
TABLE = [
    (S.SWITCH_ON_DISABLED, SHUTDOWN, S.READY_TO_SWITCH_ON, 2),
    (S.READY_TO_SWITCH_ON, SWITCH_ON_CMD, S.SWITCHED_ON, 3),
    (S.SWITCHED_ON, ENABLE_OPERATION_CMD, S.OPERATION_ENABLED, 4),
    (S.OPERATION_ENABLED, DISABLE_OPERATION, S.SWITCHED_ON, 5),
    (S.SWITCHED_ON, SHUTDOWN, S.READY_TO_SWITCH_ON, 6),
    (S.READY_TO_SWITCH_ON, DISABLE_VOLTAGE, S.SWITCH_ON_DISABLED, 7),
    (S.READY_TO_SWITCH_ON, QUICK_STOP_CMD, S.SWITCH_ON_DISABLED, 7),
    (S.OPERATION_ENABLED, SHUTDOWN, S.READY_TO_SWITCH_ON, 8),
    (S.OPERATION_ENABLED, DISABLE_VOLTAGE, S.SWITCH_ON_DISABLED, 9),
    (S.SWITCHED_ON, DISABLE_VOLTAGE, S.SWITCH_ON_DISABLED, 10),
    (S.SWITCHED_ON, QUICK_STOP_CMD, S.SWITCH_ON_DISABLED, 10),
    (S.OPERATION_ENABLED, QUICK_STOP_CMD, S.QUICK_STOP_ACTIVE, 11),
    (S.QUICK_STOP_ACTIVE, DISABLE_VOLTAGE, S.SWITCH_ON_DISABLED, 12),
]


@pytest.mark.parametrize("start, cw, end, number", TABLE)
def test_each_transition_of_the_profiles_table(start, cw, end, number):
    d = _at(start)
    assert d.write(cw) is end and d.transitions[-1] == number
    assert State.of(d.statusword) is end  # the master reads back the state the drive is in


def test_a_controlword_the_state_does_not_take_changes_nothing():
    d = _at(S.SWITCH_ON_DISABLED)
    for cw in (SWITCH_ON_CMD, ENABLE_OPERATION_CMD):  # (it must be shut down first)
        assert d.write(cw) is S.SWITCH_ON_DISABLED
    assert command(0x0B) == "quick stop" and command(0x0D) == "disable voltage"  # (quick stop is active low)
    assert command(0x0E) == "shutdown" and command(0x8F) == "enable operation"


def test_torque_only_while_enabled_or_stopping_and_the_voltage_bit_says_so():
    assert not _at(S.SWITCHED_ON).torque_on and _at(S.SWITCHED_ON).statusword & VOLTAGE_ENABLED
    assert _at(S.OPERATION_ENABLED).torque_on and _at(S.QUICK_STOP_ACTIVE).torque_on
    assert not _at(S.READY_TO_SWITCH_ON).statusword & VOLTAGE_ENABLED


@pytest.mark.parametrize("option, after", [(2, S.SWITCH_ON_DISABLED), (6, S.QUICK_STOP_ACTIVE)])
def test_a_quick_stop_ends_as_its_option_code_says(option, after):
    d = _at(S.QUICK_STOP_ACTIVE, option)
    assert d.write(ENABLE_OPERATION_CMD) is (S.OPERATION_ENABLED if option == 6 else S.QUICK_STOP_ACTIVE)  # 16
    d = _at(S.QUICK_STOP_ACTIVE, option)
    d.stopped()
    assert d.state is after


def test_a_fault_from_any_state_ends_in_fault_and_only_a_reset_edge_leaves_it():
    for start in (S.SWITCH_ON_DISABLED, S.SWITCHED_ON, S.OPERATION_ENABLED, S.QUICK_STOP_ACTIVE):
        d = _at(start)
        d.fault(0x8130)  # heartbeat / life guard error
        assert d.state is S.FAULT_REACTION_ACTIVE and d.transitions[-1] == 13 and d.torque_on
        assert d.write(SHUTDOWN) is S.FAULT_REACTION_ACTIVE  # the reaction runs to its end
        d.stopped()
        assert d.state is S.FAULT and d.transitions[-1] == 14 and not d.torque_on and d.fault_code == 0x8130
        for cw in (ENABLE_OPERATION_CMD, SHUTDOWN, DISABLE_VOLTAGE):  # never out of FAULT by itself
            assert d.write(cw) is S.FAULT
        assert d.write(FAULT_RESET | SHUTDOWN) is S.SWITCH_ON_DISABLED and d.transitions[-1] == 15
        assert d.fault_code == 0
    d = _at(S.OPERATION_ENABLED)
    d.fault(0x5441)
    d.write(FAULT_RESET)  # raised during the reaction: no reset then, and held high it is no edge after it
    d.stopped()
    assert d.write(FAULT_RESET) is S.FAULT
    d.write(0)
    assert d.write(FAULT_RESET) is S.SWITCH_ON_DISABLED


def test_every_statusword_names_one_state():
    for state in State:
        mask, value = state.value
        assert State.of(value) is state
    with pytest.raises(ValueError, match="names no CiA 402 state"):
        State.of(0x0B)


EDS = Path(__file__).resolve().parents[1] / "rehabkit" / "canopen" / "eds" / "cia402_servo.eds"
# what a master maps and sets on each drive: (index, subindex, PDO-mappable)
NEEDED = [(0x6040, 0, True), (0x6041, 0, True), (0x6060, 0, True), (0x6061, 0, True), (0x6064, 0, True),
          (0x606C, 0, True), (0x6071, 0, True), (0x6077, 0, True), (0x607A, 0, True), (0x60FF, 0, True),
          (0x607D, 1, False), (0x607D, 2, False), (0x6080, 0, False), (0x6072, 0, False), (0x6085, 0, False),
          (0x605A, 0, False), (0x60C2, 1, False), (0x60C2, 2, False), (0x6076, 0, False), (0x603F, 0, True),
          (0x1017, 0, False), (0x1016, 1, False), (0x1400, 1, False), (0x1600, 1, False), (0x1800, 1, False),
          (0x1A00, 8, False)]


def test_the_generic_servo_drives_eds_holds_what_a_master_maps_and_sets_as_canopen_reads_it():
    import canopen

    od = canopen.import_od(str(EDS), node_id=5)
    assert od[0x1000].default == 0x00020192  # CiA 402, a servo drive
    assert od[0x6502].default & 0x380 == 0x380  # cyclic synchronous position, velocity and torque
    for index, sub, mappable in NEEDED:
        entry = od[index] if not sub else od[index][sub]
        assert not mappable or entry.pdo_mappable, (hex(index), sub)
    assert (od[0x1400][1].default, od[0x1800][1].default, od[0x1014].default) == (0x205, 0x185, 0x85)  # node 5's


@pytest.fixture(scope="module")
def bus():
    """Two CANopen networks on one python-can virtual bus: the drives' side and the master's (their readers wait
    50 ms for a frame, not 1 s: what disconnecting one waits for)."""
    import canopen

    drive_net, master_net = canopen.Network(), canopen.Network()
    for net in (drive_net, master_net):
        net.NOTIFIER_CYCLE = 0.05
        net.connect(interface="virtual", channel="rehabkit-cia402-test", receive_own_messages=False)
    yield drive_net, master_net
    drive_net.disconnect()
    master_net.disconnect()


def test_a_drive_on_a_virtual_bus_answers_a_masters_sdo_as_its_eds_says(bus):
    import canopen

    drive_net, master_net = bus
    drive = canopen.LocalNode(3, str(EDS))
    drive_net.add_node(drive)
    machine = Drive402()
    drive.sdo[0x6041].raw = machine.statusword
    remote = canopen.RemoteNode(3, str(EDS))
    master_net.add_node(remote)
    assert remote.sdo[0x1000].raw == 0x00020192
    assert State.of(remote.sdo[0x6041].raw) is S.SWITCH_ON_DISABLED
    remote.sdo[0x6072].raw = 800  # a run's torque limit [per mille of rated], downloaded
    assert drive.sdo[0x6072].raw == 800


class _Joint:
    """A joint that records the torques it is given (the plant comes with the backend)."""

    def __init__(self):
        self.q, self.qd, self.applied = 0.5, -0.25, []

    def apply(self, torque):
        self.applied.append(torque)

    def read(self):
        return self.q, self.qd, self.applied[-1] if self.applied else 0.0


def test_a_simulated_drive_follows_the_masters_pdos_on_sync_and_drives_its_joint_only_when_enabled(bus):
    """The master maps the PDOs by SDO as a CANopen master does, starts the node, and walks the drive to OPERATION
    ENABLED with controlwords in an RPDO, one SYNC each; the TPDO answers with the statusword and the joint's state in
    the drive's units (and to an SDO read as they stand); a fault's EMCY reaches the master and the torque goes off."""
    import canopen

    from rehabkit.canopen.config import DriveUnits
    from rehabkit.canopen.simulated.drive import SimulatedDrive

    drive_net, master_net = bus
    joint = _Joint()
    drive = SimulatedDrive(drive_net, 4, joint, DriveUnits(counts_per_rad=1000.0, rated_torque_nm=20.0))
    remote = canopen.RemoteNode(4, str(EDS))
    master_net.add_node(remote)
    remote.tpdo.read()
    remote.rpdo.read()
    tx, tx2, rx = remote.tpdo[1], remote.tpdo[2], remote.rpdo[1]
    for pdo, indices in ((tx, (0x6041, 0x6064)), (tx2, (0x606C, 0x6077)), (rx, (0x6040, 0x6071))):
        pdo.clear()  # (at most 64 bits a PDO)
        for index in indices:
            pdo.add_variable(index)
    for pdo in (tx, tx2, rx):
        pdo.trans_type, pdo.enabled = 1, True  # synchronous, every SYNC
    remote.tpdo.save()
    remote.rpdo.save()
    remote.nmt.state = "OPERATIONAL"
    states = []
    for cw in (SHUTDOWN, SWITCH_ON_CMD, ENABLE_OPERATION_CMD):
        rx["Controlword"].raw, rx["Target torque"].raw = cw, 250  # 25 % of the rated torque
        rx.transmit()
        master_net.sync.transmit()
        assert tx2.wait_for_reception(2.0) is not None  # (the drive sends its TPDOs in order: the last one in, all)
        states.append(State.of(tx["Statusword"].raw))
    assert states == [S.READY_TO_SWITCH_ON, S.SWITCHED_ON, S.OPERATION_ENABLED]
    assert joint.applied == [0.0, 0.0, 5.0]  # 250 ‰ of 20 N·m, once the power stage is on
    assert (tx["Position actual value"].raw, tx2["Velocity actual value"].raw) == (500, -250)
    assert tx2["Torque actual value"].raw == 250  # what the joint applies, back in ‰ of the rated torque
    drive.fault(0x7305)  # incremental sensor 1 fault
    master_net.sync.transmit()
    assert tx2.wait_for_reception(2.0) is not None
    assert [e.code for e in remote.emcy.active] == [0x7305]  # the master's EMCY consumer has it
    # no quick stop deceleration set (0x6085 = 0): the reaction has no ramp, the torque goes off at once
    assert State.of(tx["Statusword"].raw) is S.FAULT and remote.sdo[0x603F].raw == 0x7305
    assert joint.applied[-1] == 0.0
    assert drive.syncs == 4


def test_a_simulated_drive_faults_when_the_masters_heartbeat_it_watches_goes_silent(bus):
    """The master tells the drive to watch its heartbeat (0x1016: node 0x7F, 10 ms) and sets a 2 ms cycle (0x1006);
    while it beats each cycle nothing happens; silent, the drive faults on its own once more than 10 ms of its clock
    have passed since the last beat (at the 5th SYNC without one: 12 ms), with the heartbeat error's EMCY."""
    import canopen

    from rehabkit.canopen.simulated.drive import HEARTBEAT_LOST, SimulatedDrive

    drive_net, master_net = bus
    drive = SimulatedDrive(drive_net, 6, _Joint(), clocked=True)  # (its consumer on its own clock: the SYNCs')
    remote = canopen.RemoteNode(6, str(EDS))
    master_net.add_node(remote)
    remote.sdo[0x1006].raw = 2000  # [µs]
    remote.sdo[0x1016][1].raw = 0x7F << 16 | 10
    tx = remote.tpdo[1]  # the statusword every SYNC: the master knows the drive has taken each cycle in
    tx.read()
    tx.clear()
    tx.add_variable(0x6041)
    tx.trans_type, tx.enabled = 1, True
    tx.save()
    remote.nmt.state = "OPERATIONAL"

    def cycle(beat: bool) -> None:
        if beat:  # the master's heartbeat (NMT state operational)
            master_net.send_message(0x77F, bytes([0x05]))
        master_net.sync.transmit()
        assert tx.wait_for_reception(2.0) is not None

    for _ in range(20):  # beating every cycle
        cycle(beat=True)
    assert drive.syncs == 20 and drive.machine.fault_code == 0
    silent = 0
    while drive.machine.fault_code == 0 and silent < 50:
        cycle(beat=False)
        silent += 1
    assert drive.machine.fault_code == HEARTBEAT_LOST and silent == 5
    assert any(e.code == HEARTBEAT_LOST for e in remote.emcy.active)  # (sent before the cycle's TPDO)
