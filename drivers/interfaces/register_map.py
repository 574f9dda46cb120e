"""The servo drive's Modbus register map: the wire contract shared by driver and twin.

It is part of ``drivers.interfaces`` (not of the concrete driver) because the twin
server implements the same contract; docs/register-map.md is its human-readable copy
and the raw-socket protocol test checks the addresses against that document
independently, so a wrong constant here cannot hide behind both sides agreeing.

All registers are holding registers (function 3 read, 6/16 write), 0-based PDU
addresses.  32-bit values span two registers, **high word first** (big-endian word
order, "ABCD"), the most common convention of servo drives.
"""

from __future__ import annotations

import enum

# --------------------------------------------------------------------------- addresses

CONTROL_WORD = 0  #: uint16 RW, see ControlBit
# -- read-only block 1..7: one request reads the whole status snapshot (1..6)
STATUS_WORD = 1  #: uint16 R, see StatusBit
ACTUAL_POSITION = 2  #: int32 R (2..3), counts, the drive's motor encoder
ACTUAL_VELOCITY = 4  #: int32 R (4..5), counts/s
FAULT_CODE = 6  #: uint16 R, see FaultCode
FIRMWARE_ID = 7  #: uint16 R, 0xMMmm = major.minor
# -- read/write block 8..17: one request writes a whole move (8..13)
TARGET_POSITION = 8  #: int32 RW (8..9), counts
PROFILE_VELOCITY = 10  #: uint32 RW (10..11), counts/s (0: the drive's default)
PROFILE_ACCELERATION = 12  #: uint32 RW (12..13), counts/s^2 (0: the drive's default)
WATCHDOG_COUNTER = 14  #: uint16 RW, the master changes it at least every WATCHDOG_TIMEOUT_MS
WATCHDOG_TIMEOUT_MS = 15  #: uint16 RW, 0 disables the watchdog (power-on value)
FOLLOWING_ERROR_LIMIT = 16  #: uint32 RW (16..17), counts

#: number of registers the drive implements (0..REGISTER_COUNT-1); others answer "illegal address"
REGISTER_COUNT = 18

#: the block a driver reads for one status snapshot: status word .. fault code
STATUS_BLOCK_START = STATUS_WORD
STATUS_BLOCK_COUNT = FAULT_CODE - STATUS_WORD + 1

#: firmware id the twin reports (1.2)
TWIN_FIRMWARE_ID = 0x0102


class ControlBit(enum.IntFlag):
    """Control word bits.  ENABLE is a level; the others act on their rising edge."""

    ENABLE = 1 << 0
    START_MOVE = 1 << 1  #: move to TARGET_POSITION with the profile registers
    STOP = 1 << 2  #: decelerate to a stop
    HOME = 1 << 3  #: reference search; sets HOMED, the position is then 0 at the reference
    FAULT_RESET = 1 << 4  #: acknowledge a fault whose cause is gone


class StatusBit(enum.IntFlag):
    """Status word bits."""

    READY = 1 << 0  #: powered, no fault, can be enabled
    ENABLED = 1 << 1
    MOVING = 1 << 2
    IN_POSITION = 1 << 3  #: enabled, not moving, at the target
    HOMED = 1 << 4
    FAULT = 1 << 5  #: FAULT_CODE says why
    FOLLOWING_ERROR = 1 << 6
    ESTOP = 1 << 7  #: emergency-stop chain open


class FaultCode(enum.IntEnum):
    """Fault codes in FAULT_CODE (0 = none).  Vendor-like numbering, documented in register-map.md."""

    NONE = 0x0000
    FOLLOWING_ERROR = 0x0010
    WATCHDOG_EXPIRED = 0x0011  #: the master stopped changing WATCHDOG_COUNTER
    ESTOP = 0x0012
    POSITION_LIMIT = 0x0013  #: target outside the soft limits
    OVERCURRENT = 0x0020
    OVERTEMPERATURE = 0x0021
    MOTOR_ENCODER = 0x0022

    @classmethod
    def describe(cls, code: int) -> str:
        try:
            return _FAULT_TEXT[cls(code)]
        except ValueError:
            return f"vendor fault 0x{code:04X}"


_FAULT_TEXT = {
    FaultCode.NONE: "no fault",
    FaultCode.FOLLOWING_ERROR: "following error: the axis lagged its command beyond the limit",
    FaultCode.WATCHDOG_EXPIRED: "communication watchdog expired",
    FaultCode.ESTOP: "emergency stop",
    FaultCode.POSITION_LIMIT: "target outside the soft limits",
    FaultCode.OVERCURRENT: "motor overcurrent",
    FaultCode.OVERTEMPERATURE: "drive overtemperature",
    FaultCode.MOTOR_ENCODER: "motor encoder fault",
}


def int32_to_regs(value: int) -> list[int]:
    """Split a signed 32-bit integer into two registers, high word first."""
    if not -(2**31) <= value < 2**31:
        raise OverflowError(f"{value} does not fit an int32 register pair")
    u = value & 0xFFFFFFFF
    return [u >> 16, u & 0xFFFF]


def uint32_to_regs(value: int) -> list[int]:
    if not 0 <= value < 2**32:
        raise OverflowError(f"{value} does not fit a uint32 register pair")
    return [value >> 16, value & 0xFFFF]


def regs_to_int32(high: int, low: int) -> int:
    u = ((high & 0xFFFF) << 16) | (low & 0xFFFF)
    return u - 2**32 if u & 0x80000000 else u


def regs_to_uint32(high: int, low: int) -> int:
    return ((high & 0xFFFF) << 16) | (low & 0xFFFF)
