"""The whole inner surface: what the coverage scan found and the unrolled picture of the bore.

A coverage scan (``station.inspection.surface_scan``) looks at the bore wall in rings of
frames; each frame's defects (``station.vision.defects``) are placed on the part, merged
across the frames that saw them, and measured again re-centred; the frames are
stitched into one picture of the unrolled wall. This module holds the results and
their JSON form (the record's ``surface`` document, docs/surface.md).

The picture: a grey image (uint8), one row per ``mm_per_px`` of axial position from
``axial_from_mm`` (top) to ``axial_to_mm`` (bottom), one column per ``mm_per_px`` of
wall (arc length at the bore's radius) from ``angle_from_deg`` (left) round to
``angle_to_deg`` (right; angles on the table, as every place the station reports).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np


@dataclass
class SurfaceDefect:
    """One defect on the part, as the station measured it.

    ``axial_mm`` / ``angle_deg``: where on the part (the centroid; for a rim defect, its
    middle on the rim); ``position_u_mm``: expanded uncertainty (k = 2) of the place on
    the unrolled wall. ``length_mm`` (the size judged: a pore's greatest Feret diameter,
    a scratch's length, a burr's or chip's length along the rim) with ``size_u_mm``
    (expanded, k = 2); ``width_mm``. ``hole``: the spec hole whose rim it is on (burrs,
    chips). ``zone``: the spec's surface zone it lies in (None: elsewhere). ``frames``:
    how many frames saw it. ``rejects``: the criterion it breaks, if any."""

    id: str
    kind: str
    axial_mm: float
    angle_deg: float
    length_mm: float
    width_mm: float
    size_u_mm: float
    position_u_mm: float
    confidence: float
    hole: str | None = None
    zone: str | None = None
    frames: int = 1
    rejects: str | None = None
    #: simulation only: the twin's defect this one is (an annotation for tests and benches)
    truth: dict | None = None

    def to_json(self, with_truth: bool = False) -> dict:
        d = {k: v for k, v in self.__dict__.items() if k != "truth"}
        for k, v in list(d.items()):
            if isinstance(v, float):
                d[k] = round(v, 5) if math.isfinite(v) else None
        if with_truth and self.truth is not None:
            d["truth"] = self.truth
        return d


@dataclass
class SurfacePicture:
    """The stitched, unrolled picture of the bore wall (see the module's docstring)."""

    image: np.ndarray  # uint8, rows = axial, columns = wall
    mm_per_px: float
    axial_from_mm: float
    angle_from_deg: float
    bore_radius_mm: float

    @property
    def height_px(self) -> int:
        return int(self.image.shape[0])

    @property
    def width_px(self) -> int:
        return int(self.image.shape[1])

    @property
    def axial_to_mm(self) -> float:
        return self.axial_from_mm + self.height_px * self.mm_per_px

    @property
    def deg_per_px(self) -> float:
        return math.degrees(self.mm_per_px / self.bore_radius_mm)

    @property
    def angle_to_deg(self) -> float:
        return self.angle_from_deg + self.width_px * self.deg_per_px

    def px_of(self, axial_mm: float, angle_deg: float) -> tuple[float, float]:
        """(x, y) in the picture's pixels (centres at integers) of a place on the part."""
        x = ((angle_deg - self.angle_from_deg) % 360.0) / self.deg_per_px - 0.5
        y = (axial_mm - self.axial_from_mm) / self.mm_per_px - 0.5
        return x, y

    def meta(self) -> dict:
        return {"mm_per_px": self.mm_per_px, "deg_per_px": self.deg_per_px, "axial_from_mm": self.axial_from_mm,
                "axial_to_mm": self.axial_to_mm, "angle_from_deg": self.angle_from_deg,
                "angle_to_deg": self.angle_to_deg, "bore_radius_mm": self.bore_radius_mm,
                "width_px": self.width_px, "height_px": self.height_px}


@dataclass
class SurfaceResult:
    """What the coverage scan found: the defects, the picture, and how it was made
    (``frames``: coverage frames; ``recentred``: frames taken re-centred on a defect;
    ``axial_from_mm``/``axial_to_mm``: the band scanned; ``coverage``: the share of that
    band's wall inside some frame's usable area; ``blur_px``: the camera's blur every
    frame's defects were measured with)."""

    defects: list[SurfaceDefect] = field(default_factory=list)
    picture: SurfacePicture | None = None
    frames: int = 0
    recentred: int = 0
    axial_from_mm: float = math.nan
    axial_to_mm: float = math.nan
    coverage: float = math.nan
    #: notes for the operator (a frame that could not be analysed, a defect lost on re-centring)
    notes: list[str] = field(default_factory=list)
    #: the camera's blur (Gaussian sigma, px) given to every frame's defect detection, as
    #: the bore scan read it at the holes' edges; None: not known (no hole's edge
    #: measured, or a record older than it), each frame read its own
    blur_px: float | None = None

    def to_json(self, with_truth: bool = False) -> dict:
        return {"defects": [d.to_json(with_truth) for d in self.defects],
                "picture": None if self.picture is None else self.picture.meta(),
                "frames": self.frames, "recentred": self.recentred,
                "axial_from_mm": _finite(self.axial_from_mm), "axial_to_mm": _finite(self.axial_to_mm),
                "coverage": _finite(self.coverage), "notes": list(self.notes), "blur_px": _finite(self.blur_px)}


def _finite(v: float) -> float | None:
    return float(v) if v is not None and math.isfinite(v) else None
