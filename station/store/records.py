"""Plain data in and out of the store.

The store hands out frozen dataclasses, never ORM objects: a caller (sequencer, REST
API, CLI) can keep, pass between threads and serialise them without a session, and
cannot change a committed result by setting an attribute.
"""

from __future__ import annotations

import copy
import math
from dataclasses import asdict, dataclass, field
from datetime import datetime
from typing import Any, Mapping, Protocol

from station import __version__ as _station_version


#: the subject (and file name) of an inspection's unrolled picture of the bore wall
SURFACE_SUBJECT = "surface"


def _finite_or_none(name: str, v: float | None) -> float | None:
    if v is None:
        return None
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
        raise ValueError(f"{name} must be a finite number or None, not {v!r}")
    return float(v)


def _iso(t: datetime | None) -> str | None:
    return None if t is None else t.isoformat()


@dataclass(frozen=True)
class Traceability:
    """How a result was made: enough to reproduce or to question it later."""

    software_version: str = _station_version
    model_version: str | None = None
    compensation_version: str | None = None
    calibration_id: str | None = None
    config_hash: str | None = None
    #: the simulation scenario; None on real hardware
    scenario: str | None = None
    #: anything else worth keeping (string values)
    extra: Mapping[str, str] = field(default_factory=dict)

    def to_json(self) -> dict[str, Any]:
        data = asdict(self)
        data["extra"] = dict(self.extra)
        return data


class _CharacteristicLike(Protocol):
    id: str
    unit: str
    nominal: float
    lower_limit: float
    upper_limit: float


@dataclass(frozen=True)
class Measurement:
    """A characteristic's result as the sequencer hands it to the store.

    ``passed`` is the sequencer's verdict (its decision rule may use the uncertainty);
    the store keeps it as given, with the limits it was judged against. ``measured``
    None means the characteristic could not be measured, which must be a fail.
    """

    characteristic_id: str
    nominal: float
    lower_limit: float
    upper_limit: float
    measured: float | None
    passed: bool
    unit: str = "mm"
    #: expanded uncertainty, k = 2
    uncertainty_k2: float | None = None
    #: simulation only: the twin's true value
    true_value: float | None = None

    def __post_init__(self) -> None:
        if not self.characteristic_id or len(self.characteristic_id) > 64:
            raise ValueError(f"characteristic_id must be 1..64 characters, not {self.characteristic_id!r}")
        for name in ("nominal", "lower_limit", "upper_limit"):
            if _finite_or_none(name, getattr(self, name)) is None:
                raise ValueError(f"{self.characteristic_id}: {name} is required")
        for name in ("measured", "uncertainty_k2", "true_value"):
            _finite_or_none(f"{self.characteristic_id}: {name}", getattr(self, name))
        if not self.lower_limit < self.upper_limit:
            raise ValueError(f"{self.characteristic_id}: lower_limit {self.lower_limit} is not below "
                             f"upper_limit {self.upper_limit}")
        if self.uncertainty_k2 is not None and self.uncertainty_k2 < 0:
            raise ValueError(f"{self.characteristic_id}: uncertainty_k2 must not be negative")
        if not isinstance(self.passed, bool):
            raise ValueError(f"{self.characteristic_id}: passed must be True or False, not {self.passed!r}")
        if self.measured is None and self.passed:
            raise ValueError(f"{self.characteristic_id}: a characteristic that was not measured cannot pass")

    @classmethod
    def of(cls, characteristic: _CharacteristicLike, measured: float | None, *, passed: bool,
           uncertainty_k2: float | None = None, true_value: float | None = None) -> Measurement:
        """From a part spec's :class:`station.parts.Characteristic` (id, unit, limits)."""
        return cls(characteristic.id, characteristic.nominal, characteristic.lower_limit,
                   characteristic.upper_limit, measured, passed, characteristic.unit,
                   uncertainty_k2, true_value)


@dataclass(frozen=True)
class CharacteristicRecord:
    """A stored characteristic result."""

    characteristic_id: str
    unit: str
    nominal: float
    lower_limit: float
    upper_limit: float
    measured: float | None
    uncertainty_k2: float | None
    passed: bool
    true_value: float | None

    def to_json(self) -> dict[str, Any]:
        return asdict(self)


@dataclass(frozen=True)
class ImageRecord:
    """A stored image crop; ``path`` is relative to the store's data folder."""

    subject: str
    path: str
    sha256: str
    created_at: datetime

    def to_json(self) -> dict[str, Any]:
        return {**asdict(self), "created_at": _iso(self.created_at)}


@dataclass(frozen=True)
class FindingRecord:
    """A finding of the scan (``kind``: unexpected_hole, ambiguous_identity, datum),
    given to the store and read back the same."""

    kind: str
    message: str
    subject: str | None = None
    axial_mm: float | None = None
    angle_deg: float | None = None
    diameter_mm: float | None = None
    #: expanded uncertainty (k = 2) of the position, mm
    u_mm: float | None = None

    def __post_init__(self) -> None:
        from station.store.models import FINDING_KINDS

        if self.kind not in FINDING_KINDS:
            raise ValueError(f"finding kind must be one of {', '.join(FINDING_KINDS)}, not {self.kind!r}")
        if not isinstance(self.message, str) or not self.message:
            raise ValueError("a finding needs a message")
        if self.subject is not None and not 1 <= len(self.subject) <= 64:
            raise ValueError(f"finding subject must be 1..64 characters, not {self.subject!r}")
        for name in ("axial_mm", "angle_deg", "diameter_mm", "u_mm"):
            object.__setattr__(self, name, _finite_or_none(f"finding {name}", getattr(self, name)))

    @classmethod
    def of(cls, finding: Any) -> FindingRecord:
        """From anything with the same attributes (the scan's ``ScanFinding``)."""
        return cls(finding.kind, finding.message, getattr(finding, "subject", None),
                   getattr(finding, "axial_mm", None), getattr(finding, "angle_deg", None),
                   getattr(finding, "diameter_mm", None), getattr(finding, "u_mm", None))

    def to_json(self) -> dict[str, Any]:
        return asdict(self)


@dataclass(frozen=True)
class InspectionSummary:
    """An inspection's header, as lists show it."""

    id: str
    part_number: str
    serial: str | None
    order_id: str | None
    state: str
    result: str | None
    reason: str | None
    started_at: datetime
    finished_at: datetime | None
    traceability: Mapping[str, Any]
    idempotency_key: str | None
    #: machine time of the inspection (s) and how it divides; None when unknown
    machine_s: float | None = None
    cycle: Mapping[str, Any] | None = None
    #: the station that made it; None for records older than station ids
    station_id: str | None = None

    def to_json(self) -> dict[str, Any]:
        return {
            "id": self.id, "station_id": self.station_id, "part_number": self.part_number, "serial": self.serial, "order_id": self.order_id,
            "state": self.state, "result": self.result, "reason": self.reason,
            "started_at": _iso(self.started_at), "finished_at": _iso(self.finished_at),
            "traceability": dict(self.traceability), "idempotency_key": self.idempotency_key,
            "machine_s": self.machine_s, "cycle": None if self.cycle is None else dict(self.cycle),
        }


@dataclass(frozen=True)
class InspectionRecord(InspectionSummary):
    """An inspection with its characteristic results, image crops and the scan's
    findings, in recording order."""

    characteristics: tuple[CharacteristicRecord, ...] = ()
    images: tuple[ImageRecord, ...] = ()
    findings: tuple[FindingRecord, ...] = ()
    #: the whole-surface inspection's document as stored (``SurfaceResult.to_json``:
    #: defects, the picture's meta, coverage; docs/surface.md); None when there was none
    surface: Mapping[str, Any] | None = None

    def surface_image(self) -> ImageRecord | None:
        """The unrolled picture of the bore wall, when the record has one."""
        if self.surface is None or self.surface.get("picture") is None:
            return None
        for i in self.images:
            if i.subject == SURFACE_SUBJECT and i.path.endswith(f"/{SURFACE_SUBJECT}.png"):
                return i
        return None

    def characteristic(self, characteristic_id: str) -> CharacteristicRecord:
        for c in self.characteristics:
            if c.characteristic_id == characteristic_id:
                return c
        raise KeyError(f"inspection {self.id} has no result for {characteristic_id!r}")

    def to_json(self) -> dict[str, Any]:
        return {**super().to_json(),
                "characteristics": [c.to_json() for c in self.characteristics],
                "images": [i.to_json() for i in self.images],
                "findings": [f.to_json() for f in self.findings],
                "surface": None if self.surface is None else copy.deepcopy(dict(self.surface))}


@dataclass(frozen=True)
class EventRecord:
    """One entry of the append-only event log."""

    id: int
    inspection_id: str | None
    at: datetime
    kind: str
    message: str
    #: the station that logged it; None for events older than station ids
    station_id: str | None = None

    def to_json(self) -> dict[str, Any]:
        return {**asdict(self), "at": _iso(self.at)}
