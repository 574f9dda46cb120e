"""The servo drive's Modbus register map: the wire contract shared by driver and twin.

It is part of ``drivers.interfaces`` (not of the concrete driver) because the twin
server implements the same contract; docs/register-map.md is its human-readable copy
and the raw-socket protocol test checks the addresses against that document
independently, so a wrong constant here cannot hide behind both sides agreeing.

All registers are holding registers (function 3 read, 6/16 write), 0-based PDU
addresses.  32-bit values span two registers, **high word first** (big-endian word
order, "ABCD"), the most common convention of servo drives.

The map is a declaration (:data:`REGISTERS`): each :class:`Field` states its
address, width (16 or 32 bits), signedness and scale (raw, or counts of the axis'
``unit_per_count``), and decodes and encodes itself; :class:`Block` is a run of
fields read or written in one request (:data:`STATUS_BLOCK`, :data:`MOVE_BLOCK`).
The plain address constants (``ACTUAL_POSITION`` ...) are derived from it.
``tests/unit/test_register_map.py`` checks the declaration against the document's
table.
"""

from __future__ import annotations

import enum
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass

# --------------------------------------------------------------------------- the declaration


class Scale(enum.Enum):
    """How a register's integer becomes a value."""

    #: as it is: bits, a code, a counter, milliseconds
    RAW = "raw"
    #: counts: times the axis' ``unit_per_count`` (mm or deg per count; per s, per s^2
    #: for the velocity and acceleration registers)
    COUNTS = "counts"


@dataclass(frozen=True)
class Field:
    """One value in the map: where it is, how wide, signed or not, how it scales.

    ``width`` is 16 (one register) or 32 bits (two registers, high word first);
    ``units`` and ``access`` ("R" or "RW") are docs/register-map.md's columns."""

    name: str
    address: int
    width: int = 16
    signed: bool = False
    scale: Scale = Scale.RAW
    units: str = ""
    access: str = "R"

    def __post_init__(self):
        if self.width not in (16, 32):
            raise ValueError(f"{self.name}: a register field is 16 or 32 bits wide, not {self.width}")
        if self.access not in ("R", "RW"):
            raise ValueError(f"{self.name}: access is 'R' or 'RW', not {self.access!r}")
        if not 0 <= self.address <= 0xFFFF:
            raise ValueError(f"{self.name}: address {self.address} is not a Modbus register address")

    @property
    def count(self) -> int:
        """How many registers the field spans."""
        return self.width // 16

    @property
    def addresses(self) -> range:
        return range(self.address, self.address + self.count)

    @property
    def type(self) -> str:
        """``int32``, ``uint16``, ...: the document's name of the type."""
        return f"{'int' if self.signed else 'uint'}{self.width}"

    @property
    def writable(self) -> bool:
        return self.access == "RW"

    # -- integers <-> registers

    def decode_raw(self, regs: Sequence[int]) -> int:
        """The field's integer from its ``count`` registers (each taken as 16 bits)."""
        if len(regs) != self.count:
            raise ValueError(f"{self.name} spans {self.count} register(s), not {len(regs)}")
        return _from_regs(regs, self.width, self.signed)

    def encode_raw(self, value: int) -> list[int]:
        """The registers of the integer ``value``; OverflowError if it does not fit."""
        return _to_regs(int(value), self.width, self.signed, self.name)

    # -- values <-> registers

    def _factor(self, unit_per_count: float | None) -> float | None:
        if self.scale is Scale.RAW:
            return None
        if unit_per_count is None or not unit_per_count > 0:
            raise ValueError(f"{self.name} is in counts: give the axis' unit_per_count")
        return float(unit_per_count)

    def decode(self, regs: Sequence[int], unit_per_count: float | None = None) -> int | float:
        """The field's value: an int for a raw field, counts x ``unit_per_count`` for one in counts."""
        raw = self.decode_raw(regs)
        factor = self._factor(unit_per_count)
        return raw if factor is None else raw * factor

    def encode(self, value: float, unit_per_count: float | None = None) -> list[int]:
        """The registers of ``value`` (in the axis unit for a field in counts: rounded
        to the nearest count)."""
        factor = self._factor(unit_per_count)
        return self.encode_raw(int(value) if factor is None else int(round(value / factor)))


@dataclass(frozen=True)
class Block:
    """Fields at contiguous addresses, read or written in one request (the status
    snapshot 1..6, a whole move 8..13)."""

    name: str
    fields: tuple[Field, ...]

    def __post_init__(self):
        if not self.fields:
            raise ValueError(f"block {self.name} has no fields")
        for a, b in zip(self.fields, self.fields[1:]):
            if b.address != a.address + a.count:
                raise ValueError(f"block {self.name}: {b.name} does not follow {a.name}")

    @property
    def start(self) -> int:
        return self.fields[0].address

    @property
    def count(self) -> int:
        return sum(f.count for f in self.fields)

    def _split(self, regs: Sequence[int]):
        if len(regs) != self.count:
            raise ValueError(f"block {self.name} spans {self.count} registers, not {len(regs)}")
        for f in self.fields:
            i = f.address - self.start
            yield f, regs[i:i + f.count]

    def decode_raw(self, regs: Sequence[int]) -> dict[str, int]:
        """Every field's integer, by name."""
        return {f.name: f.decode_raw(part) for f, part in self._split(regs)}

    def decode(self, regs: Sequence[int], unit_per_count: float | None = None) -> dict[str, int | float]:
        """Every field's value, by name (fields in counts scaled by ``unit_per_count``)."""
        return {f.name: f.decode(part, unit_per_count) for f, part in self._split(regs)}

    def encode_raw(self, values: Mapping[str, int]) -> list[int]:
        """The block's registers from every field's integer, by name."""
        missing = [f.name for f in self.fields if f.name not in values]
        extra = set(values) - {f.name for f in self.fields}
        if missing or extra:
            raise KeyError(f"block {self.name}: missing {missing}, unknown {sorted(extra)}")
        return [r for f in self.fields for r in f.encode_raw(values[f.name])]


class RegisterMap:
    """The drive's fields, by name (``REGISTERS["TARGET_POSITION"]`` or
    ``REGISTERS.TARGET_POSITION``); no two fields share a register."""

    def __init__(self, fields: Sequence[Field]):
        self._fields = {f.name: f for f in fields}
        if len(self._fields) != len(fields):
            raise ValueError("two register fields share a name")
        taken: dict[int, str] = {}
        for f in fields:
            for a in f.addresses:
                if a in taken:
                    raise ValueError(f"{f.name} and {taken[a]} share register {a}")
                taken[a] = f.name

    def __getitem__(self, name: str) -> Field:
        return self._fields[name]

    def __getattr__(self, name: str) -> Field:
        try:
            return self.__dict__["_fields"][name]
        except KeyError:
            raise AttributeError(name) from None

    def __iter__(self) -> Iterator[Field]:
        return iter(sorted(self._fields.values(), key=lambda f: f.address))

    def __len__(self) -> int:
        return len(self._fields)

    @property
    def register_count(self) -> int:
        """Registers the drive implements (0 .. register_count - 1)."""
        return max(f.address + f.count for f in self._fields.values())

    def at(self, address: int) -> Field | None:
        """The field that holds register ``address``, if any."""
        for f in self._fields.values():
            if address in f.addresses:
                return f
        return None

    def block(self, name: str, *field_names: str) -> Block:
        return Block(name, tuple(self[n] for n in field_names))


#: the map itself: docs/register-map.md's table, row by row
REGISTERS = RegisterMap((
    Field("CONTROL_WORD", 0, 16, False, Scale.RAW, "bits", "RW"),  # see ControlBit
    # -- read-only block 1..7: one request reads the whole status snapshot (1..6)
    Field("STATUS_WORD", 1, 16, False, Scale.RAW, "bits", "R"),  # see StatusBit
    Field("ACTUAL_POSITION", 2, 32, True, Scale.COUNTS, "counts", "R"),  # the drive's motor encoder
    Field("ACTUAL_VELOCITY", 4, 32, True, Scale.COUNTS, "counts/s", "R"),
    Field("FAULT_CODE", 6, 16, False, Scale.RAW, "code", "R"),  # see FaultCode
    Field("FIRMWARE_ID", 7, 16, False, Scale.RAW, "0xMMmm", "R"),  # major.minor
    # -- read/write block 8..17: one request writes a whole move (8..13)
    Field("TARGET_POSITION", 8, 32, True, Scale.COUNTS, "counts", "RW"),
    Field("PROFILE_VELOCITY", 10, 32, False, Scale.COUNTS, "counts/s", "RW"),  # 0: the drive's default
    Field("PROFILE_ACCELERATION", 12, 32, False, Scale.COUNTS, "counts/s^2", "RW"),  # 0: the drive's default
    Field("WATCHDOG_COUNTER", 14, 16, False, Scale.RAW, "-", "RW"),  # changed at least every WATCHDOG_TIMEOUT_MS
    Field("WATCHDOG_TIMEOUT_MS", 15, 16, False, Scale.RAW, "ms", "RW"),  # 0 disables the watchdog (power-on)
    Field("FOLLOWING_ERROR_LIMIT", 16, 32, False, Scale.COUNTS, "counts", "RW"),
))

#: one status snapshot: status word .. fault code (1..6), one request
STATUS_BLOCK = REGISTERS.block("status", "STATUS_WORD", "ACTUAL_POSITION", "ACTUAL_VELOCITY", "FAULT_CODE")
#: one move: target, velocity, acceleration (8..13), one request
MOVE_BLOCK = REGISTERS.block("move", "TARGET_POSITION", "PROFILE_VELOCITY", "PROFILE_ACCELERATION")

# --------------------------------------------------------------------------- addresses
# the start address of each field, as plain ints (the twin indexes its register list by them)

CONTROL_WORD = REGISTERS.CONTROL_WORD.address
STATUS_WORD = REGISTERS.STATUS_WORD.address
ACTUAL_POSITION = REGISTERS.ACTUAL_POSITION.address
ACTUAL_VELOCITY = REGISTERS.ACTUAL_VELOCITY.address
FAULT_CODE = REGISTERS.FAULT_CODE.address
FIRMWARE_ID = REGISTERS.FIRMWARE_ID.address
TARGET_POSITION = REGISTERS.TARGET_POSITION.address
PROFILE_VELOCITY = REGISTERS.PROFILE_VELOCITY.address
PROFILE_ACCELERATION = REGISTERS.PROFILE_ACCELERATION.address
WATCHDOG_COUNTER = REGISTERS.WATCHDOG_COUNTER.address
WATCHDOG_TIMEOUT_MS = REGISTERS.WATCHDOG_TIMEOUT_MS.address
FOLLOWING_ERROR_LIMIT = REGISTERS.FOLLOWING_ERROR_LIMIT.address

#: number of registers the drive implements (0..REGISTER_COUNT-1); others answer "illegal address"
REGISTER_COUNT = REGISTERS.register_count

#: the block a driver reads for one status snapshot: status word .. fault code
STATUS_BLOCK_START = STATUS_BLOCK.start
STATUS_BLOCK_COUNT = STATUS_BLOCK.count

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


# --------------------------------------------------------------------------- codecs


def _to_regs(value: int, width: int, signed: bool, what: str = "") -> list[int]:
    lo, hi = (-(2 ** (width - 1)), 2 ** (width - 1)) if signed else (0, 2**width)
    if not lo <= value < hi:
        kind = f"{'int' if signed else 'uint'}{width}"
        raise OverflowError(f"{value} does not fit {what + ' ' if what else ''}({kind})")
    u = value & ((1 << width) - 1)
    return [(u >> shift) & 0xFFFF for shift in range(width - 16, -1, -16)]  # high word first


def _from_regs(regs: Sequence[int], width: int, signed: bool) -> int:
    u = 0
    for r in regs:  # high word first; each register taken as its 16 bits
        u = (u << 16) | (int(r) & 0xFFFF)
    return u - (1 << width) if signed and u >> (width - 1) else u


def int32_to_regs(value: int) -> list[int]:
    """Split a signed 32-bit integer into two registers, high word first."""
    return _to_regs(value, 32, True, "an int32 register pair")


def uint32_to_regs(value: int) -> list[int]:
    return _to_regs(value, 32, False, "a uint32 register pair")


def regs_to_int32(high: int, low: int) -> int:
    return _from_regs((high, low), 32, True)


def regs_to_uint32(high: int, low: int) -> int:
    return _from_regs((high, low), 32, False)
