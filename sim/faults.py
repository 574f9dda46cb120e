"""Fault injection for every twin: what can go wrong on a real station, switchable at run time.

Each twin owns a :class:`FaultSwitch`; a test, the CLI or a scenario turns faults on and
off while the twin runs (from any thread).  What a fault *means* depends on the twin:

========================  ===========================================  =================================
kind                      servo drive (Modbus)                         grating encoder (serial)
========================  ===========================================  =================================
DROP_CONNECTION           open connections closed, new ones closed     the head stops answering
                          on their first request (cable pulled)        (serial line cut)
DELAY                     every reply late by ``delay_s``              every reply late by ``delay_s``
GARBAGE                   reply bytes replaced by noise                reply replaced by a noise line
CHECKSUM                  frame corrupted: RTU CRC / MBAP protocol id  valid frame, wrong checksum
STUCK_AXIS                the motor jams: a move ends in a following   the count freezes and the head
                          error fault                                  flags SIGNAL_LOW
DRIVE_FAULT               the drive faults with ``code``               the head flags HARDWARE_ERROR
BLACK_FRAME, FROZEN_FRAME (camera twin)                                (camera twin)
========================  ===========================================  =================================
"""

from __future__ import annotations

import enum
import threading
from dataclasses import dataclass
from typing import Callable


class FaultKind(enum.Enum):
    DROP_CONNECTION = "drop_connection"
    DELAY = "delay"
    GARBAGE = "garbage"
    CHECKSUM = "checksum"
    STUCK_AXIS = "stuck_axis"
    DRIVE_FAULT = "drive_fault"
    BLACK_FRAME = "black_frame"
    FROZEN_FRAME = "frozen_frame"


#: the faults each kind of twin understands
MODBUS_DRIVE_FAULTS = frozenset(
    {
        FaultKind.DROP_CONNECTION,
        FaultKind.DELAY,
        FaultKind.GARBAGE,
        FaultKind.CHECKSUM,
        FaultKind.STUCK_AXIS,
        FaultKind.DRIVE_FAULT,
    }
)
ENCODER_FAULTS = MODBUS_DRIVE_FAULTS
CAMERA_FAULTS = frozenset({FaultKind.DROP_CONNECTION, FaultKind.DELAY, FaultKind.BLACK_FRAME, FaultKind.FROZEN_FRAME})


@dataclass(frozen=True)
class Fault:
    """An active fault and its parameters (unused parameters keep their defaults)."""

    kind: FaultKind
    #: DELAY: seconds added before each reply
    delay_s: float = 0.0
    #: DRIVE_FAULT: the fault code the drive reports (docs/register-map.md)
    code: int = 0


Listener = Callable[[FaultKind, "Fault | None"], None]


class FaultSwitch:
    """The set of faults active on one twin; thread-safe, with change listeners.

    Listeners are called (in the thread that changed the fault) with the kind and the
    new fault, or ``None`` when it was cleared; a twin uses them for faults that must
    act at once (closing connections, faulting the drive) rather than on the next request.
    """

    def __init__(self, supported: frozenset[FaultKind] = frozenset(FaultKind), name: str = "twin"):
        self.supported = frozenset(supported)
        self.name = name
        self._active: dict[FaultKind, Fault] = {}
        self._lock = threading.Lock()
        self._listeners: list[Listener] = []

    def add_listener(self, fn: Listener) -> None:
        self._listeners.append(fn)

    def activate(self, kind: FaultKind | str, **params) -> Fault:
        kind = FaultKind(kind)
        if kind not in self.supported:
            raise ValueError(f"{self.name} does not support fault {kind.value!r}")
        fault = Fault(kind, **params)
        with self._lock:
            self._active[kind] = fault
        for fn in list(self._listeners):
            fn(kind, fault)
        return fault

    def clear(self, kind: FaultKind | str | None = None) -> None:
        """Clear one fault, or all of them when ``kind`` is None."""
        with self._lock:
            kinds = list(self._active) if kind is None else [FaultKind(kind)]
            cleared = [k for k in kinds if self._active.pop(k, None) is not None]
        for k in cleared:
            for fn in list(self._listeners):
                fn(k, None)

    def get(self, kind: FaultKind) -> Fault | None:
        with self._lock:
            return self._active.get(kind)

    def is_active(self, kind: FaultKind) -> bool:
        return self.get(kind) is not None

    def active(self) -> list[Fault]:
        with self._lock:
            return list(self._active.values())
