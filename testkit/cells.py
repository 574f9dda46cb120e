"""The fault matrix's cells: which fault, where in the inspection, for how long, and
what the station must make of it (docs/reliability.md, section 1)."""

from __future__ import annotations

from dataclasses import dataclass

#: the phases of an inspection where a fault is switched on, in the order they come
PHASES = ("homing", "moving", "settling", "capturing", "measuring", "storing")

#: kinds the engine retries (the link, not the machine): they get a transient row too
TRANSIENT_KINDS = ("drop_connection", "delay", "garbage", "checksum", "black_frame", "frozen_frame")
#: every twin fault kind (``sim.faults.FaultKind`` values)
DEVICE_KINDS = ("drop_connection", "delay", "garbage", "checksum", "stuck_axis", "drive_fault",
                "black_frame", "frozen_frame")

#: a delay past each driver's timeout (Modbus 0.5 s, encoder 0.2 s, camera grab 1 s:
#: the defaults in drivers/ and sim/camera/twin.py) and one well inside it
LONG_DELAY_S = {"Z": 1.0, "encoder": 0.5, "camera": 1.5}
SHORT_DELAY_S = {"Z": 0.2, "encoder": 0.05, "camera": 0.3}
#: the drive fault a ``drive_fault`` cell raises: 0x0020, motor overcurrent
#: (docs/register-map.md)
DRIVE_FAULT_CODE = 0x20


@dataclass(frozen=True)
class Cell:
    """One cell of the matrix: a fault kind (a ``FaultKind`` value, or ``store_*`` /
    ``vision_error`` for the failures that are not a twin's), the phase where it is
    switched on, and whether it lasts for one call only (``transient``)."""

    kind: str
    phase: str
    transient: bool = False

    @property
    def id(self) -> str:
        return f"{self.kind}-{self.phase}" + ("-once" if self.transient else "")

    @property
    def device(self) -> str:
        """The twin the fault is switched on: "Z", "encoder" or "camera" (or "store", "vision")."""
        if self.kind.startswith("store"):
            return "store"
        if self.kind == "vision_error":
            return "vision"
        if self.kind in ("black_frame", "frozen_frame"):
            return "camera"
        if self.phase == "capturing" and self.kind in ("drop_connection", "delay"):
            return "camera"
        if self.phase == "measuring":
            return "encoder"
        return "Z"

    @property
    def expected(self) -> str:
        """What must happen: "complete" (the result is right despite the fault) or "faulted"."""
        if self.transient:
            return "complete"
        if self.phase == "storing":
            # a device fault after the scan does not touch the result; a store that
            # cannot commit ends the inspection faulted (the result is not reported)
            return "faulted" if self.device == "store" else "complete"
        return "faulted"


def matrix_cells() -> list[Cell]:
    """Every cell: each device kind in each phase, the transient kinds once in each
    phase but storing, and the three failures that are not a twin's."""
    cells = [Cell(k, p) for k in DEVICE_KINDS for p in PHASES]
    cells += [Cell(k, p, True) for k in TRANSIENT_KINDS for p in PHASES if p != "storing"]
    cells += [Cell("store_unavailable", "storing"), Cell("store_disk_full", "storing"),
              Cell("vision_error", "measuring")]
    return cells
