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


class SurfacePicture(OpenModel):
    """The unrolled picture of the bore wall: where its pixels are on the part, and where
    to get it. Row 0 is ``axial_from_mm``, column 0 ``angle_from_deg``; a place (axial
    mm, angle deg) is at x = ((angle - angle_from_deg) mod 360) / deg_per_px,
    y = (axial - axial_from_mm) / mm_per_px, in pixels from the picture's top left
    corner (a pixel's centre at +0.5)."""

    url: str = Field(description="the picture (PNG, grey): `GET /api/v1/inspections/{id}/surface.png`")
    mm_per_px: Number = Field(description="mm of axial position per row, and of wall (arc length) per column")
    deg_per_px: Number = Field(description="degrees of angle per column (mm_per_px at the bore's radius)")
    axial_from_mm: Number = Field(description="axial position of the picture's top edge, from the datum face")
    axial_to_mm: Number = Field(description="axial position of its bottom edge")
    angle_from_deg: Number = Field(description="angle on the table of its left edge")
    angle_to_deg: Number = Field(description="angle of its right edge (may pass 360)")
    bore_radius_mm: Number
    width_px: int
    height_px: int


class SurfaceDefect(OpenModel):
    """One defect the surface inspection found on the part (docs/api.md, Surface)."""

    id: str
    kind: str = Field(description="pore, scratch, burr or chip")
    axial_mm: Number | None = Field(description="where: axial position from the datum face (the centroid; "
                                                "a rim defect's middle on the rim)")
    angle_deg: Number | None = Field(description="where: angle on the table")
    length_mm: Number | None = Field(description="the size judged: a pore's greatest Feret diameter, a "
                                                 "scratch's length, a burr's or chip's length along the rim")
    width_mm: Number | None
    size_u_mm: Number | None = Field(description="expanded uncertainty (k = 2) of length_mm")
    position_u_mm: Number | None = Field(description="expanded uncertainty (k = 2) of the place on the wall")
    confidence: Number | None = Field(description="the detector's confidence, 0..1")
    hole: str | None = Field(description="the spec hole whose rim it is on (burrs, chips); null: none")
    zone: str | None = Field(description="the spec's surface zone it lies in; null: elsewhere")
    frames: int = Field(description="how many frames saw it")
    rejects: str | None = Field(description="the part spec's criterion it breaks; null: none")


class Surface(OpenModel):
    """The whole-surface inspection: a coverage scan of the bore wall stitched into one
    unrolled picture, and the defects found on it (docs/api.md, Surface)."""

    picture: SurfacePicture | None = Field(description="null: no picture was made")
    defects: list[SurfaceDefect] = Field(description="in the order the station reports them")
    frames: int = Field(description="coverage frames taken")
    recentred: int = Field(description="frames taken re-centred on a defect, to measure it again")
    axial_from_mm: Number | None = Field(description="the band of the bore scanned, from")
    axial_to_mm: Number | None = Field(description="the band of the bore scanned, to")
    coverage: Number | None = Field(description="share of that band's wall inside some frame's usable area, 0..1")
    notes: list[str] = Field(description="for the operator: a frame that could not be analysed, ...")
    blur_px: Number | None = Field(default=None, description="the camera's blur (Gaussian sigma, px) every frame's "
                                                             "defects were measured with, read at the holes' edges "
                                                             "in the bore scan; null: not known (each frame read "
                                                             "its own) or a record older than it")


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
    """The job response: an inspection with its characteristics, image digests, findings
    and surface inspection."""

    characteristics: list[Characteristic]
    images: list[ImageDigest]
    findings: list[Finding] = Field(description="in the scan's order")
    surface: Surface | None = Field(description="the whole-surface inspection: the defects and the unrolled "
                                                "picture; null when the part spec asks for none, or the "
                                                "inspection did not complete")


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
