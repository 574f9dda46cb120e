"""Job responses: an inspection as ``GET /inspections/{id}`` and the job order's answer
show it, the list's items, and the stations of the database (docs/api.md)."""

from __future__ import annotations

from typing import Any

from pydantic import Field

from api.schemas.common import ClosedModel, IsoTime, Links, Number, OpenModel


class Cycle(OpenModel):
    """How the machine time divides (``station.sequencer.cycle.cycle_summary``), as the
    record stored it: the store takes any object, so every key is optional here and a
    key the record lacks is absent from the answer. A number JSON cannot carry (a ratio
    to a zero bound) is null."""

    machine_s: Number | None = Field(default=None, description="machine time of the run, s")
    basis: str | None = Field(default=None,
                              description="`measured` on hardware, `modelled` under a twin's time scale")
    breakdown: dict[str, Number | None] | None = Field(
        default=None, description="s per kind of step: moves_s, settle_s, frames_s, vision_s, other_s")
    lower_bound_s: Number | None = Field(
        default=None, description="the least the same plan could cost, s (only when the axes' limits and the "
                                  "camera's timing are known)")
    ratio: Number | None = Field(default=None, description="machine_s / lower_bound_s (with lower_bound_s)")
    lower_bound_breakdown: dict[str, Number | None] | None = Field(
        default=None, description="the lower bound's breakdown, s (with lower_bound_s)")


class Characteristic(ClosedModel):
    """One characteristic's result, with the limits it was judged against."""

    id: str = Field(description="`<hole id>.<kind>`, e.g. `hole_1.position`")
    unit: str = Field(description="unit of nominal, limits, measured and uncertainty (mm)")
    nominal: Number
    lower_limit: Number
    upper_limit: Number
    measured: Number | None = Field(description="null: could not be measured (then a fail)")
    uncertainty_k2: Number | None = Field(description="expanded uncertainty, k = 2")
    passed: bool = Field(alias="pass", description="the station's verdict on this characteristic")


class ImageDigest(ClosedModel):
    """A stored image crop, by its digest (the picture stays in the station's data folder)."""

    subject: str
    sha256: str


class Finding(ClosedModel):
    """What the scan saw that the spec does not say (docs/api.md, Findings)."""

    kind: str = Field(description="unexpected_hole, ambiguous_identity or datum")
    message: str = Field(description="the same in words, for a person")
    subject: str | None = Field(description="the spec hole it concerns (null for an unexpected hole)")
    axial_mm: Number | None = Field(description="from the part's datum face")
    angle_deg: Number | None = Field(description="on the table")
    diameter_mm: Number | None
    u_mm: Number | None = Field(description="expanded uncertainty (k = 2) of the position")


class InspectionSummary(ClosedModel):
    """An inspection as lists show it: no characteristics, images or findings."""

    id: str
    station_id: str | None = Field(description="the station that made it (null: older than station ids)")
    part_number: str
    serial: str | None
    order_id: str | None = Field(description="the production order (ISA-95 job order id)")
    state: str = Field(description="running, complete, aborted, faulted or interrupted")
    result: str | None = Field(description="pass or fail; null until complete")
    reason: str | None = Field(description="why it ended as it did (aborted, faulted)")
    started_at: IsoTime
    finished_at: IsoTime | None
    traceability: dict[str, Any] = Field(
        description="how the result was made: software, model, compensation and calibration versions, ...")
    machine_s: Number | None = Field(description="machine time of the inspection, s; null while running or unknown")
    cycle: Cycle | None = Field(description="how machine_s divides; null while running or unknown")
    links: Links = Field(description="`self` and `qif`")


class Inspection(InspectionSummary):
    """The job response: an inspection with its characteristics, image digests and findings."""

    characteristics: list[Characteristic]
    images: list[ImageDigest]
    findings: list[Finding] = Field(description="in the scan's order")


class InspectionList(ClosedModel):
    """A page of inspections, newest first."""

    total: int = Field(description="inspections matching the filters, all pages")
    limit: int
    offset: int
    items: list[InspectionSummary]


class Stations(ClosedModel):
    """The stations writing this database."""

    this: str | None = Field(description="this station's id (null: none configured)")
    stations: list[str] = Field(description="ids of the stations whose inspections the database holds, sorted")
