"""EMCY error codes in words: the CiA 402 drive profile's (IEC 61800-7-201, annex) where a drive gives one, else
CiA 301's classes as canopen's ``EmcyError`` knows them."""

from __future__ import annotations

from canopen.emcy import EmcyError

CIA402 = {
    0x2310: "continuous over-current", 0x2320: "short circuit / earth leakage", 0x3210: "DC link over-voltage",
    0x3220: "DC link under-voltage", 0x4210: "excess temperature of the device",
    0x4310: "excess temperature of the drive", 0x5441: "safe torque off active (the drive's own safety input)",
    0x5530: "EEPROM error", 0x6320: "parameter error", 0x7121: "motor blocked", 0x7305: "incremental sensor 1 fault",
    0x8100: "communication error (a drive's SYNC stopped coming: the host's cycles)",
    0x8110: "CAN overrun (messages lost)", 0x8120: "CAN in error passive",
    0x8130: "life guard error or heartbeat error (the drive no longer hears the host's heartbeat)",
    0x8140: "recovered from bus off",
    0x8400: "velocity speed controller: beyond the max speed (0x6080)", 0x8611: "following error",
    0x8612: "reference limit: beyond the software position limits (0x607D)", 0xFF00: "device specific",
}


def describe(code: int) -> str:
    """``0x8130 life guard error or heartbeat error``: the code and what it means."""
    text = CIA402.get(code) or EmcyError(code, 0, b"", 0.0).get_desc().lower() or "unknown"
    return f"0x{code:04X} {text}"
