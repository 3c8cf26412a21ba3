"""The simulated drives against CiA 301 (NMT states and the services active in each, SDO abort codes, PDO mapping,
EMCY and the error objects, heartbeat) and CiA 402 (the state machine and its statusword masks, modes of operation
0x6060/0x6061/0x6502, abort connection option 0x6007), with the standards' numbers, over real drives' EDS/DCF files
(tests/data/canopen_eds) and rehabkit's generic servo — on a lock-step bus (tests/conformance_bench.py), the drive's
watchdogs on a clock the test moves."""

import functools

import canopen
import pytest

from rehabkit.canopen.deadlines import SYNC_TIMEOUT_MS
from tests.conformance_bench import FILES, NODE, Bench

IDS = [p.stem for p in FILES]
BOOT_UP, PRE_OPERATIONAL, OPERATIONAL, STOPPED = 0x00, 0x7F, 0x05, 0x04  # CiA 301 heartbeat state bytes
START, STOP, ENTER_PRE_OPERATIONAL, RESET_NODE, RESET_COMMUNICATION = 0x01, 0x02, 0x80, 0x81, 0x82
# CiA 402 statusword: (mask, value) of each state
SWITCH_ON_DISABLED, READY_TO_SWITCH_ON, SWITCHED_ON = (0x4F, 0x40), (0x6F, 0x21), (0x6F, 0x23)
OPERATION_ENABLED, QUICK_STOP_ACTIVE, FAULT = (0x6F, 0x27), (0x6F, 0x07), (0x4F, 0x08)
SHUTDOWN, SWITCH_ON, ENABLE_OPERATION, QUICK_STOP, FAULT_RESET = 0x06, 0x07, 0x0F, 0x02, 0x80
CONTROLWORD, STATUSWORD = 0x60400010, 0x60410010  # PDO mapping entries: index << 16 | sub << 8 | bits
CST, CSP, CSV = 10, 8, 9
TARGETS = {CST: 0x60710010, CSP: 0x607A0020, CSV: 0x60FF0020}


def _in(state, statusword: int) -> bool:
    mask, value = state
    return statusword & mask == value


@functools.cache
def _od(path):
    return canopen.import_od(str(path), NODE)


@pytest.mark.parametrize("eds", FILES, ids=IDS)
def test_boot_up_then_the_heartbeat_says_each_nmt_state(eds):
    b = Bench(eds)
    assert b.sent(0x700 + NODE) == [bytes([BOOT_UP])]  # created: its boot-up, into PRE-OPERATIONAL
    b.write(0x1017, 0, "<H", 10)
    for command, byte in ((None, PRE_OPERATIONAL), (START, OPERATIONAL), (STOP, STOPPED)):
        if command:
            b.nmt(command)
        before = len(b.sent(0x700 + NODE))
        b.sync(12)  # (on a lock-step bus its heartbeat goes on its own clock: the SYNCs it sees, ≥ 1 ms each)
        beats = b.sent(0x700 + NODE)[before:]
        assert beats and set(beats) == {bytes([byte])}


@pytest.mark.parametrize("eds", FILES, ids=IDS)
def test_stopped_answers_only_nmt_and_heartbeat(eds):
    """CiA 301: in STOPPED no SDO, no PDO, no EMCY; NMT still obeyed."""
    b = Bench(eds)
    tpdo = b.map_pdo(0x1800, [STATUSWORD])
    b.nmt(STOP)
    b.sync(3)
    b.drive.fault(0x5441)
    answers = len(b.sent(0x580 + NODE))
    b.master.send_message(0x600 + NODE, bytes([0x40, 0x00, 0x10, 0, 0, 0, 0, 0]))
    assert len(b.sent(0x580 + NODE)) == answers and not b.sent(tpdo) and not b.emcys()
    b.nmt(ENTER_PRE_OPERATIONAL)
    assert b.abort(b.read, 0x1017, 0, "<H") is None and b.read(0x1001, 0, "<B") & 0x01  # (the fault's)


def _aborts(path):
    """(what, the call, its arguments, the abort code CiA 301 gives it) for the file's dictionary."""
    od = _od(path)
    missing = next(i for i in range(0x2FFF, 0x2000, -1) if i not in od)
    rows = [("missing object", "read", (missing, 0, "<I"), 0x06020000),
            ("missing sub-index", "read", (0x1018, max(od[0x1018].subindices) + 1, "<I"), 0x06090011),
            ("write a read-only object", "write", (0x6041, 0, "<H", 0), 0x06010002),
            ("read a write-only object", "read", (0x5FFF, 0, "<B"), 0x06010001),
            ("length too high", "write", (0x6040, 0, "<I", 6), 0x06070012),
            ("length too low", "write", (0x6040, 0, "<B", 6), 0x06070013)]
    mode = od[0x6060]
    rows.append(("mode 99", "write", (0x6060, 0, "<b", 99),
                 0x06090031 if mode.max is not None and mode.max < 99 else 0x06090030))
    for index, value, fmt in ((0x605A, 9, "<h"), (0x6007, 4, "<h")):  # (option codes beyond the EDS's HighLimit)
        if index in od and od[index].max is not None and od[index].max < value:
            rows.append((f"0x{index:04X} = {value}", "write", (index, 0, fmt, value), 0x06090031))
    if od[0x6085].min is not None and od[0x6085].min > 0:
        rows.append(("0x6085 below its LowLimit", "write", (0x6085, 0, "<I", od[0x6085].min - 1), 0x06090032))
    return rows


@pytest.mark.parametrize("eds", FILES, ids=IDS)
def test_sdo_abort_codes(eds):
    b = Bench(eds)
    got = {what: b.abort(getattr(b, call), *args) for what, call, args, _ in _aborts(eds)}
    assert got == {what: code for what, _, _, code in _aborts(eds)}


@pytest.mark.parametrize("eds", FILES, ids=IDS)
def test_modes_of_operation_only_the_supported_and_the_display_follows_at_once(eds):
    """CiA 402: 0x6061 shows the mode in effect; 0x6502 bit (mode - 1) says a mode is supported (bit 4 reserved);
    where the EDS gives 0x6502 no value the simulated drive supports PP, PV, HM, CSP, CSV, CST (0x3A5)."""
    b, od = Bench(eds), _od(eds)
    supported = b.read(0x6502, 0, "<I")
    assert supported == (od[0x6502].value or od[0x6502].default or 0x3A5)
    for mode in range(1, 11):
        if od[0x6060].max is not None and mode > od[0x6060].max:
            continue
        code = b.abort(b.write, 0x6060, 0, "<b", mode)
        if mode != 5 and supported >> (mode - 1) & 1:
            assert code is None and b.read(0x6061, 0, "<b") == mode  # (no SYNC between: at once)
        else:
            assert code == 0x06090030, mode


@pytest.mark.parametrize("eds", FILES, ids=IDS)
def test_pdo_mapping_rules_and_the_default_maps(eds):
    """CiA 301: a PDO maps only objects that exist and may be mapped (0x06040041), at most 64 bits (0x06040042); a
    default map's number of entries (sub-index 0) is what it maps."""
    b, od = Bench(eds), _od(eds)
    for index in [i for i in range(0x1600, 0x1C00) if i in od and (i < 0x1800 or i >= 0x1A00)]:
        n = b.read(index, 0, "<B")
        entries = [b.read(index, k, "<I") for k in range(1, n + 1)]
        assert all(entries), (hex(index), n, entries)
    not_mappable = next(v for i in (0x1000, 0x1018, 0x6085, 0x6502) if i in od
                        for v in (od[i] if isinstance(od[i], canopen.objectdictionary.ODVariable) else od[i][1],)
                        if not v.pdo_mappable)
    missing = next(i for i in range(0x2FFF, 0x2000, -1) if i not in od)
    b.write(0x1800, 1, "<I", b.read(0x1800, 1, "<I") | 0x80000000)
    b.write(0x1A00, 0, "<B", 0)
    entry = not_mappable.index << 16 | not_mappable.subindex << 8 | len(not_mappable)
    assert b.abort(b.write, 0x1A00, 1, "<I", entry) == 0x06040041
    assert b.abort(b.write, 0x1A00, 1, "<I", missing << 16 | 0x20) == 0x06040041
    assert b.abort(b.write, 0x1A00, 1, "<I", 0x60640010) == 0x06040041  # (a 32-bit object as 16 bits)
    for k in (1, 2, 3):
        b.write(0x1A00, k, "<I", 0x60640020)
    assert b.abort(b.write, 0x1A00, 0, "<B", 3) == 0x06040042  # 96 bits
    assert b.abort(b.write, 0x1A00, 0, "<B", 2) is None


@pytest.mark.parametrize("eds", [p for p in FILES if 0x1003 in _od(p)], ids=lambda p: p.stem)
def test_each_emcy_is_in_the_error_register_and_history_and_a_fault_reset_sends_the_error_reset(eds):
    b = Bench(eds)
    b.drive.fault(0x2310)  # continuous over-current: generic and current bits
    assert b.emcys() == [(0x2310, 0x03)] and b.read(0x1001, 0, "<B") == 0x03
    assert (b.read(0x1003, 0, "<B"), b.read(0x1003, 1, "<I") & 0xFFFF) == (1, 0x2310)
    b.sync()  # (the reaction ends: FAULT)
    assert _in(FAULT, b.statusword())
    b.write(0x6040, 0, "<H", 0)
    b.write(0x6040, 0, "<H", FAULT_RESET)
    assert _in(SWITCH_ON_DISABLED, b.statusword())
    assert b.emcys()[-1] == (0x0000, 0x00) and b.read(0x1001, 0, "<B") == 0
    b.drive.fault(0x7305)
    assert [b.read(0x1003, k, "<I") & 0xFFFF for k in (1, 2)] == [0x7305, 0x2310]  # newest first
    assert b.read(0x1003, 0, "<B") == 2 and b.abort(b.write, 0x1003, 0, "<B", 1) == 0x06090030
    b.write(0x1003, 0, "<B", 0)  # (0 clears the history)
    assert b.read(0x1003, 0, "<B") == 0


@pytest.mark.parametrize("eds", FILES, ids=IDS)
def test_the_controlword_acts_by_sdo_at_once_and_from_a_synchronous_rpdo_at_the_next_sync(eds):
    b = Bench(eds)
    assert _in(SWITCH_ON_DISABLED, b.statusword())
    for cw, state in ((SHUTDOWN, READY_TO_SWITCH_ON), (SWITCH_ON, SWITCHED_ON), (ENABLE_OPERATION, OPERATION_ENABLED)):
        b.write(0x6040, 0, "<H", cw)  # in PRE-OPERATIONAL, no SYNC
        assert _in(state, b.statusword()), hex(b.statusword())
    rpdo = b.map_pdo(0x1400, [CONTROLWORD])
    b.nmt(START)
    b.master.send_message(rpdo, QUICK_STOP.to_bytes(2, "little"))
    assert _in(OPERATION_ENABLED, b.statusword())  # (taken at the SYNC, not before)
    b.sync()
    assert _in(QUICK_STOP_ACTIVE, b.statusword()) or _in(SWITCH_ON_DISABLED, b.statusword())


@pytest.mark.parametrize("eds", FILES, ids=IDS)
def test_nmt_resets_restore_their_objects_and_boot_again(eds):
    b, od = Bench(eds), _od(eds)
    b.write(0x1017, 0, "<H", 7)
    decel = od[0x6085]
    b.write(0x6085, 0, "<I", (decel.min or 1) + 1)
    for cw in (SHUTDOWN, SWITCH_ON):
        b.write(0x6040, 0, "<H", cw)
    b.nmt(RESET_COMMUNICATION)
    assert b.sent(0x700 + NODE).count(bytes([BOOT_UP])) == 2
    assert b.read(0x1017, 0, "<H") == (od[0x1017].value if od[0x1017].value is not None else od[0x1017].default)
    assert b.read(0x6085, 0, "<I") == (decel.min or 1) + 1 and _in(SWITCHED_ON, b.statusword())
    b.nmt(RESET_NODE)
    assert b.sent(0x700 + NODE).count(bytes([BOOT_UP])) == 3
    assert b.read(0x6085, 0, "<I") == (decel.value if decel.value is not None else decel.default or 0)
    assert _in(SWITCH_ON_DISABLED, b.statusword())


def _enabled(b: Bench, option: int, consumer_ms: int = 60) -> int:
    """The drive OPERATIONAL, OPERATION ENABLED through its RPDO, watching the master's heartbeat; its RPDO."""
    b.write(0x6007, 0, "<h", option)
    b.write(0x1016, 1, "<I", 0x7F << 16 | consumer_ms)
    rpdo = b.map_pdo(0x1400, [CONTROLWORD])
    b.map_pdo(0x1800, [STATUSWORD])
    b.nmt(START)
    for cw in (0, SHUTDOWN, SWITCH_ON, ENABLE_OPERATION):
        b.heartbeat()
        b.master.send_message(rpdo, cw.to_bytes(2, "little"))
        b.sync()
    assert _in(OPERATION_ENABLED, b.statusword())
    return rpdo


@pytest.mark.parametrize("option, after", [(1, FAULT), (2, SWITCH_ON_DISABLED), (3, QUICK_STOP_ACTIVE)])
def test_a_master_that_vanishes_meets_the_abort_connection_option_every_time(option, after):
    """CiA 402 0x6007: the SYNC stops while the drive is enabled: EMCY 0x8100 (communication error) and the option's
    reaction (1 fault, 2 disable voltage, 3 quick stop) — the 1st, 2nd and 3rd time, after each recovery."""
    b = Bench()
    rpdo = _enabled(b, option)
    for time in range(3):
        b.t += SYNC_TIMEOUT_MS * 1e-3 + 0.001  # (past the SYNC watchdog's default, within the heartbeat's 60 ms)
        b.drive.poll()
        assert [c for c, _ in b.emcys()].count(0x8100) == time + 1
        if option == 1:
            b.sync()  # (the reaction to its end)
        assert _in(after, b.statusword())
        for cw in (FAULT_RESET, 0, SHUTDOWN, SWITCH_ON, ENABLE_OPERATION):  # the master back, as it recovers
            b.heartbeat()
            b.master.send_message(rpdo, cw.to_bytes(2, "little"))
            b.sync()
        assert _in(OPERATION_ENABLED, b.statusword())


def test_the_heartbeat_consumer_starts_with_the_first_heartbeat_runs_in_pre_operational_and_rearms():
    b = Bench()
    b.write(0x1016, 1, "<I", 0x7F << 16 | 50)
    b.t += 1.0
    b.drive.poll()
    assert not b.emcys()  # (no heartbeat yet: not active)
    for time in range(2):
        b.heartbeat()
        b.t += 0.051
        b.drive.poll()  # PRE-OPERATIONAL, no SYNC: on its clock
        assert [c for c, _ in b.emcys()].count(0x8130) == time + 1 and _in(FAULT, b.statusword() | 0x0F) is False
        b.sync()
        b.write(0x6040, 0, "<H", 0)
        b.write(0x6040, 0, "<H", FAULT_RESET)
    b.write(0x1016, 1, "<I", 0)  # disarmed
    b.heartbeat()
    b.t += 1.0
    b.drive.poll()
    assert [c for c, _ in b.emcys()].count(0x8130) == 2


def test_a_master_ending_its_run_in_order_leaves_a_drive_that_raises_no_emcy():
    """quick stop → shutdown → 0x1016 disarmed → NMT pre-operational → heartbeat and SYNC stop: no EMCY, however
    long after. Without the disarm the drive's consumer (on its clock, in PRE-OPERATIONAL) reports the silence."""
    for disarm in (True, False):
        b = Bench()
        rpdo = _enabled(b, option=1)
        for cw in (QUICK_STOP, SHUTDOWN):
            b.heartbeat()
            b.master.send_message(rpdo, cw.to_bytes(2, "little"))
            b.sync()
        assert _in(READY_TO_SWITCH_ON, b.statusword())
        if disarm:
            b.write(0x1016, 1, "<I", 0)
        b.nmt(ENTER_PRE_OPERATIONAL)
        for _ in range(100):
            b.t += 0.1
            b.drive.poll()
        assert b.emcys() == ([] if disarm else [(0x8130, 0x11)])  # (communication error: register bits 0, 4)


@pytest.mark.parametrize("eds, mode", [(p, m) for p in FILES for m in (CST, CSP, CSV)
                                       if (_od(p)[0x6502].value or _od(p)[0x6502].default or 0x3A5) >> (m - 1) & 1
                                       and TARGETS[m] >> 16 in _od(p)], ids=lambda x: getattr(x, "stem", str(x)))
def test_each_cyclic_mode_drives_the_joint_toward_its_target(eds, mode):
    b = Bench(eds)
    b.write(0x6060, 0, "<b", mode)
    assert b.read(0x6061, 0, "<b") == mode
    rpdo = b.map_pdo(0x1400, [CONTROLWORD, TARGETS[mode]])
    b.nmt(START)
    size = (TARGETS[mode] & 0xFF) // 8
    for cw in (SHUTDOWN, SWITCH_ON, ENABLE_OPERATION, ENABLE_OPERATION):
        b.master.send_message(rpdo, cw.to_bytes(2, "little") + (100).to_bytes(size, "little"))
        b.sync()
    assert _in(OPERATION_ENABLED, b.statusword()) and b.joint.applied[-1] > 0
