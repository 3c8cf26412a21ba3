"""The CiA 402 drive state machine against the profile's transition table (IEC 61800-7-201, figure "state machine")."""

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
