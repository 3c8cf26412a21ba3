"""A simulated device's errors as CiA 301 has a device keep and say them: the error register (0x1001), the
pre-defined error field (0x1003: its error history, newest first, sub-index 0 the number kept; writing 0 there clears
it) and an EMCY for each error, and one with error code 0x0000 and register 0 once no error is left (the "error
reset"). EMCYs go out only in PRE-OPERATIONAL and OPERATIONAL (CiA 301: the EMCY service is not active in STOPPED).

A latched error (a drive's fault) stays until a fault reset (:meth:`ErrorLog.reset`); a passing one (a connection
lost that the drive met without a fault) until the connection is back (:meth:`ErrorLog.recover`).
"""

from __future__ import annotations

from collections.abc import Callable

from rehabkit.canopen.simulated.device import INVALID_VALUE, Device

# the error register's bits (CiA 301): 0 generic (with every error), 1 current, 2 voltage, 3 temperature,
# 4 communication, 7 manufacturer-specific
GENERIC, CURRENT, VOLTAGE, TEMPERATURE, COMMUNICATION, MANUFACTURER = 0x01, 0x02, 0x04, 0x08, 0x10, 0x80


def register_bits(code: int) -> int:
    """The error register's bits an error code sets (its class, CiA 301's table of error codes)."""
    if code >> 12 == 0x2:
        return GENERIC | CURRENT
    if code >> 12 == 0x3:
        return GENERIC | VOLTAGE
    if code >> 12 == 0x4:
        return GENERIC | TEMPERATURE
    if code >> 8 in (0x81, 0x82):
        return GENERIC | COMMUNICATION
    if code >> 8 == 0xFF:
        return GENERIC | MANUFACTURER
    return GENERIC


class ErrorLog:
    """``device``'s errors (see the module's doc); ``may_send()``: its NMT state lets it send an EMCY."""

    def __init__(self, device: Device, may_send: Callable[[], bool]):
        self.device, self.may_send = device, may_send
        od = device.object_dictionary
        self.size = max((s for s in od[0x1003].subindices), default=0) if 0x1003 in od else 0
        self.active: dict[int, bool] = {}  # error code → latched
        self.history: list[int] = []  # newest first
        self.raised: list[int] = []  # every error code it raised, in order (the device's own log)
        device.checks.append(self._check)

    @property
    def register(self) -> int:
        """0x1001: the bits of every active error."""
        bits = 0
        for code in self.active:
            bits |= register_bits(code)
        return bits

    def raise_error(self, code: int, latched: bool = True) -> None:
        """An error: kept in the register and the history, its EMCY sent."""
        self.active[code] = latched or self.active.get(code, False)
        self.raised.append(code)
        if self.size:
            self.history = [code, *self.history][: self.size]
        self._send(code)

    def recover(self, code: int) -> None:
        """A passing error's cause is gone."""
        if code in self.active and not self.active[code]:
            del self.active[code]
            if not self.active:
                self._send(0x0000)

    def reset(self) -> None:
        """A fault reset: every error cleared, the error reset's EMCY sent."""
        if self.active:
            self.active.clear()
            self._send(0x0000)

    def clear_history(self) -> None:
        self.history = []

    def _send(self, code: int) -> None:
        if self.may_send():
            self.device.emcy.send(code, self.register)

    def read(self, index: int, subindex: int) -> int | None:
        """0x1001 and 0x1003 as they stand (None: not one of them)."""
        if index == 0x1001:
            return self.register
        if index == 0x1003:
            if subindex == 0:
                return len(self.history)
            return self.history[subindex - 1] if subindex <= len(self.history) else 0
        return None

    def _check(self, index: int, subindex: int, value: int) -> int | None:
        if index == 0x1003 and subindex == 0:  # (only 0 may be written: it clears the history)
            if value:
                return INVALID_VALUE
            self.clear_history()
        return None
