"""The CiA 402 drive state machine (IEC 61800-7-201/-301, the CANopen drive profile), as a servo drive runs it:
the controlword (0x6040) a master writes moves it, the statusword (0x6041) says where it is, a fault takes it through
FAULT REACTION ACTIVE to FAULT, and only a fault reset's rising edge (controlword bit 7) leaves FAULT. The quick stop
option code (0x605A) says whether a quick stop ends disabled or stays in QUICK STOP ACTIVE.

Used by the simulated drives (the drive side) and read by the canopen backend (the master side), so both agree on
every transition of the profile's table, numbered as the profile numbers them.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from enum import Enum
from functools import lru_cache


class State(Enum):
    """The drive's states, each with the statusword bits that say it: (mask, value) over bits 0-3, 5, 6."""

    NOT_READY_TO_SWITCH_ON = (0x4F, 0x00)
    SWITCH_ON_DISABLED = (0x4F, 0x40)
    READY_TO_SWITCH_ON = (0x6F, 0x21)
    SWITCHED_ON = (0x6F, 0x23)
    OPERATION_ENABLED = (0x6F, 0x27)
    QUICK_STOP_ACTIVE = (0x6F, 0x07)
    FAULT_REACTION_ACTIVE = (0x4F, 0x0F)
    FAULT = (0x4F, 0x08)

    @classmethod
    def of(cls, statusword: int) -> State:
        """The state a statusword says (the master's reading of it; each cycle, each drive: cached)."""
        return _state_of(statusword)


@lru_cache(maxsize=256)
def _state_of(statusword: int) -> State:
    for state in State:
        mask, value = state.value
        if statusword & mask == value:
            return state
    raise ValueError(f"statusword 0x{statusword:04X} names no CiA 402 state")


# statusword bits besides the state's
VOLTAGE_ENABLED, WARNING, REMOTE, TARGET_REACHED, INTERNAL_LIMIT = 0x10, 0x80, 0x200, 0x400, 0x800
# controlword bits
SWITCH_ON, ENABLE_VOLTAGE, QUICK_STOP, ENABLE_OPERATION, FAULT_RESET = 0x01, 0x02, 0x04, 0x08, 0x80
# controlword commands (the bits 0-3 they set; quick stop is active low)
SHUTDOWN = ENABLE_VOLTAGE | QUICK_STOP  # 0x06
SWITCH_ON_CMD = SHUTDOWN | SWITCH_ON  # 0x07
ENABLE_OPERATION_CMD = SWITCH_ON_CMD | ENABLE_OPERATION  # 0x0F
DISABLE_VOLTAGE = 0x00
QUICK_STOP_CMD = ENABLE_VOLTAGE  # 0x02
DISABLE_OPERATION = SWITCH_ON_CMD  # 0x07

# quick stop option codes (0x605A) that stay in QUICK STOP ACTIVE once stopped (else: on to SWITCH ON DISABLED)
STAY_IN_QUICK_STOP = frozenset((5, 6, 7, 8))
TORQUE_STATES = frozenset((State.OPERATION_ENABLED, State.QUICK_STOP_ACTIVE, State.FAULT_REACTION_ACTIVE))


def command(controlword: int) -> str:
    """The device control command of a controlword (bits 0-3, as the profile's table decodes them: every pattern is
    one)."""
    cw = controlword & 0x0F
    if not cw & ENABLE_VOLTAGE:
        return "disable voltage"
    if not cw & QUICK_STOP:
        return "quick stop"
    if cw & 0x07 == SHUTDOWN:
        return "shutdown"
    # "switch on" is also "disable operation": the same bits, read by the state they arrive in
    return "switch on" if cw == SWITCH_ON_CMD else "enable operation"


@dataclass
class Drive402:
    """One drive's state machine. ``quick_stop_option``: 0x605A. The drive side calls :meth:`write` with each
    controlword, :meth:`fault` when it detects one, :meth:`stopped` when a quick stop or fault reaction has brought
    the motor to rest; :attr:`statusword` is what it reports. ``transitions`` keeps each transition's number."""

    quick_stop_option: int = 2
    state: State = State.NOT_READY_TO_SWITCH_ON
    fault_code: int = 0  # the error code (0x603F) of the fault it is in, if any
    transitions: list[int] = field(default_factory=list)
    _last_cw: int = 0

    def __post_init__(self) -> None:
        self._go(State.SWITCH_ON_DISABLED, 1)  # (transitions 0 and 1: initialised, it waits for the master)

    @property
    def statusword(self) -> int:
        """The state's bits, remote (it takes the master's controlword) and voltage enabled while its power stage is
        on (switched on and the states after it)."""
        word = self.state.value[1] | REMOTE
        if self.state in (State.SWITCHED_ON, *TORQUE_STATES):
            word |= VOLTAGE_ENABLED
        return word

    @property
    def torque_on(self) -> bool:
        """The power stage drives the motor (operation enabled, or stopping it)."""
        return self.state in TORQUE_STATES

    def _go(self, state: State, transition: int) -> None:
        self.state = state
        self.transitions.append(transition)

    def write(self, controlword: int) -> State:
        """A controlword from the master: the transition it asks for, where the profile allows one."""
        rising_reset = controlword & FAULT_RESET and not self._last_cw & FAULT_RESET
        self._last_cw = controlword
        s, cmd = self.state, command(controlword)
        if s is State.FAULT:
            if rising_reset:  # only a fault reset leaves FAULT, never by itself
                self.fault_code = 0
                self._go(State.SWITCH_ON_DISABLED, 15)
            return self.state
        if s is State.FAULT_REACTION_ACTIVE or controlword & FAULT_RESET:
            return self.state
        if s is State.SWITCH_ON_DISABLED and cmd == "shutdown":
            self._go(State.READY_TO_SWITCH_ON, 2)
        elif s is State.READY_TO_SWITCH_ON:
            if cmd in ("switch on", "enable operation"):
                self._go(State.SWITCHED_ON, 3)
                if cmd == "enable operation":  # (3 then 4: a master may enable in one word)
                    self._go(State.OPERATION_ENABLED, 4)
            elif cmd in ("disable voltage", "quick stop"):
                self._go(State.SWITCH_ON_DISABLED, 7)
        elif s is State.SWITCHED_ON:
            if cmd == "enable operation":
                self._go(State.OPERATION_ENABLED, 4)
            elif cmd == "shutdown":
                self._go(State.READY_TO_SWITCH_ON, 6)
            elif cmd in ("disable voltage", "quick stop"):
                self._go(State.SWITCH_ON_DISABLED, 10)
        elif s is State.OPERATION_ENABLED:
            if cmd == "switch on":  # disable operation
                self._go(State.SWITCHED_ON, 5)
            elif cmd == "shutdown":
                self._go(State.READY_TO_SWITCH_ON, 8)
            elif cmd == "disable voltage":
                self._go(State.SWITCH_ON_DISABLED, 9)
            elif cmd == "quick stop":
                self._go(State.QUICK_STOP_ACTIVE, 11)
        elif s is State.QUICK_STOP_ACTIVE:
            if cmd == "disable voltage":
                self._go(State.SWITCH_ON_DISABLED, 12)
            elif cmd == "enable operation" and self.quick_stop_option in STAY_IN_QUICK_STOP:
                self._go(State.OPERATION_ENABLED, 16)
        return self.state

    def quick_stop_locally(self) -> None:
        """The drive's own quick stop (its abort connection option code says so when its master falls silent):
        from OPERATION ENABLED to QUICK STOP ACTIVE (transition 11); elsewhere its power stage is already off."""
        if self.state is State.OPERATION_ENABLED:
            self._go(State.QUICK_STOP_ACTIVE, 11)

    def disable_locally(self) -> None:
        """The drive's own enable input opened (no fault): its power stage off, to SWITCH ON DISABLED (as transition
        9 or 12 would take it there; the master must walk it up again)."""
        if self.state not in (State.FAULT_REACTION_ACTIVE, State.FAULT, State.SWITCH_ON_DISABLED):
            self._go(State.SWITCH_ON_DISABLED, 9 if self.state is State.OPERATION_ENABLED else 12)

    def fault(self, code: int) -> None:
        """The drive detected a fault (``code``: its 0x603F error code): from any state, its reaction begins."""
        if self.state in (State.FAULT_REACTION_ACTIVE, State.FAULT):
            return
        self.fault_code = code
        self._go(State.FAULT_REACTION_ACTIVE, 13)

    def stopped(self) -> None:
        """The motor has come to rest after a quick stop or a fault reaction: the state that follows it."""
        if self.state is State.FAULT_REACTION_ACTIVE:
            self._go(State.FAULT, 14)
        elif self.state is State.QUICK_STOP_ACTIVE and self.quick_stop_option not in STAY_IN_QUICK_STOP:
            self._go(State.SWITCH_ON_DISABLED, 12)
