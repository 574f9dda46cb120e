"""What a part must be: the validated model of a part spec file.

A part spec names the bore and, for every compensating hole, the two characteristics
the station measures (diameter and axial position) with their tolerances. The
sequencer plans the scan from the holes, and the results store copies each
characteristic's nominal and limits into the inspection record, so that a record
stays readable after the spec file changes.

Pydantic v2 validates the file; unknown keys are refused (``extra="forbid"``) because
a misspelt tolerance key silently ignored would inspect parts against the wrong limits.
Numbers are strict (TOML strings are not numbers) and must be finite (TOML allows
``inf`` and ``nan``).
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from decimal import Decimal
from typing import Literal

from pydantic import BaseModel, ConfigDict, Field, field_validator, model_validator

#: hole ids become characteristic ids (``hole_1.diameter``) and image names: keep
#: them lowercase identifiers so they are safe in file names, URLs and QIF ids
HOLE_ID_PATTERN = r"^[a-z][a-z0-9_]{0,31}$"
#: part numbers name the built-in spec files (``<part number>.toml``): no path
#: separators, no leading dot
PART_NUMBER_PATTERN = r"^[A-Za-z0-9][A-Za-z0-9._-]{0,63}$"

#: the two characteristics measured on each compensating hole (paper, Table 4)
CHARACTERISTIC_KINDS = ("diameter", "position")

#: a hole's angular search band when the drawing gives no angular tolerance (deg, +/-):
#: the drawing does not bound the angle, so the band is as wide as one frame searches
#: at no extra cost: the 12.8 mm wide frame shows a 0.825 mm hole whole, with 0.2 mm
#: clearance, within +/-5.8 mm of wall, +/-30 deg on the 22.2 mm bore; 25 deg leaves
#: room for the part's placement. A hole further round is an unexpected one, not this
#: hole (docs/part-specs.md, Search zones); a drawing's angle_tol_deg replaces it
DEFAULT_ANGLE_TOL_DEG = 25.0


def _decimal_sum(a: float, b: float) -> float:
    """``a + b`` as the nearest double to the decimal sum of the numbers as written.

    Binary floats make 71.03 + 0.1 come out as 71.13000000000001; a measurement of
    exactly 71.130 (paper, Table 4, hole 1 before compensation) must compare against
    the limit a person reads on the drawing, 71.13. ``repr`` gives the shortest decimal
    that round-trips, which for TOML literals is the literal itself.
    """
    return float(Decimal(repr(a)) + Decimal(repr(b)))


class SpecProblems(ValueError):
    """Problems found across fields (after each field was valid on its own), each with
    the field it belongs to, so that a file's report names every one precisely."""

    def __init__(self, problems: list[tuple[tuple, str]]):
        self.problems = problems
        super().__init__("; ".join(f"{'.'.join(map(str, loc))}: {msg}" for loc, msg in problems))


class _SpecModel(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True, strict=True, allow_inf_nan=False)


class Tolerance(_SpecModel):
    """A nominal value with either a symmetric ``tol`` (nominal ± tol) or separate
    signed deviations ``upper`` and ``lower`` (limits nominal + upper, nominal + lower,
    as on a drawing: 0.7 +0.1/-0.05 is ``upper = 0.1, lower = -0.05``)."""

    nominal: float
    tol: float | None = Field(default=None, description="symmetric tolerance: nominal ± tol (mm)")
    upper: float | None = Field(default=None, description="upper deviation from nominal (mm, signed)")
    lower: float | None = Field(default=None, description="lower deviation from nominal (mm, signed)")

    @field_validator("tol")
    @classmethod
    def _tol_positive(cls, v: float | None) -> float | None:
        if v is not None and not v > 0:
            raise ValueError(f"must be positive (got {v})")
        return v

    @model_validator(mode="after")
    def _one_form(self) -> Tolerance:
        asym = (self.upper is not None, self.lower is not None)
        if self.tol is not None and any(asym):
            raise ValueError("give either tol (symmetric ±) or upper and lower, not both")
        if self.tol is None:
            if not any(asym):
                raise ValueError("needs a tolerance: tol (symmetric ±) or upper and lower")
            if not all(asym):
                missing = "lower" if self.lower is None else "upper"
                raise ValueError(f"upper and lower go together: {missing} is missing")
            if not self.upper > self.lower:
                raise ValueError(f"upper ({self.upper}) must be above lower ({self.lower})")
        return self

    @property
    def lower_limit(self) -> float:
        dev = -self.tol if self.tol is not None else self.lower
        return _decimal_sum(self.nominal, dev)

    @property
    def upper_limit(self) -> float:
        dev = self.tol if self.tol is not None else self.upper
        return _decimal_sum(self.nominal, dev)


class Bore(_SpecModel):
    """The cylinder bore the endoscope enters."""

    diameter_mm: float
    depth_mm: float

    @field_validator("diameter_mm", "depth_mm")
    @classmethod
    def _positive(cls, v: float) -> float:
        if not v > 0:
            raise ValueError(f"must be positive (got {v})")
        return v


class Hole(_SpecModel):
    """A compensating hole: its diameter and its axial position (distance of its centre
    from the part's datum face, the face that sits on the rotary table), both in mm,
    and the nominal angle about the bore axis where it lies."""

    id: str = Field(pattern=HOLE_ID_PATTERN)
    angle_deg: float = Field(description="nominal angle about the bore axis, [0, 360) deg")
    #: the drawing's angular tolerance of the hole's place (+/- deg); not a measured
    #: characteristic, it bounds where the station looks for the hole
    angle_tol_deg: float | None = Field(default=None, description="angular tolerance of the hole's place, +/- deg")
    diameter: Tolerance
    position: Tolerance

    @property
    def angle_search_deg(self) -> float:
        """Half-width of the angular band the hole is looked for in, about its drawing
        angle (before the part's placement uncertainty is added)."""
        return self.angle_tol_deg if self.angle_tol_deg is not None else DEFAULT_ANGLE_TOL_DEG

    @field_validator("angle_tol_deg")
    @classmethod
    def _angle_tol_range(cls, v: float | None) -> float | None:
        if v is not None and not 0.0 < v < 180.0:
            raise ValueError(f"must be in (0, 180) deg (got {v})")
        return v

    @field_validator("angle_deg")
    @classmethod
    def _angle_range(cls, v: float) -> float:
        if not 0.0 <= v < 360.0:
            raise ValueError(f"must be in [0, 360) deg (got {v})")
        return v

    @field_validator("diameter")
    @classmethod
    def _diameter_positive(cls, v: Tolerance) -> Tolerance:
        if not v.lower_limit > 0:
            raise ValueError(f"the lower limit {v.lower_limit:g} mm must be above 0: a hole has a size")
        return v


class Placement(_SpecModel):
    """How well the part's place on the rotary table is known: with the position
    tolerance it bounds each hole's search zone (docs/part-specs.md, Search zones).

    ``axial_mm``: the uncertainty of the part's axial place beyond the position
    tolerance (the datum face on the table: a chip under it, the face's flatness),
    and how far out of tolerance a hole is still measured as that hole rather than
    reported as an unexpected one.  ``angle_deg``: the uncertainty of the part's angle
    on the table when an angular fixture places it.  ``angular_datum``: no fixture;
    the part's angle is set by this hole, found by a survey round the bore at its
    axial band, and the other holes are looked for at their drawing angles from it
    (``angle_deg`` is then not used)."""

    axial_mm: float = Field(default=0.5, ge=0.0, le=10.0)
    angle_deg: float = Field(default=5.0, ge=0.0, le=180.0)
    angular_datum: str | None = Field(default=None, pattern=HOLE_ID_PATTERN)


#: the surface's defect kinds a criterion may limit (docs/surface.md); burrs and chips
#: are judged at the compensating holes' rims, pores and scratches on the wall
SURFACE_WALL_KINDS = ("pore", "scratch")
SURFACE_RIM_KINDS = ("burr", "chip")


class _SurfaceLimits(_SpecModel):
    """The largest defect of each kind allowed (mm: a pore's greatest Feret diameter, a
    scratch's length); None: that kind is not limited there."""

    max_pore_mm: float | None = None
    max_scratch_mm: float | None = None

    @field_validator("max_pore_mm", "max_scratch_mm")
    @classmethod
    def _positive_limit(cls, v: float | None) -> float | None:
        if v is not None and not v > 0:
            raise ValueError(f"must be positive (got {v}); leave it out to set no limit")
        return v


class SurfaceZone(_SurfaceLimits):
    """A band of the bore with its own limits (a sealing zone: where the cups run), from
    ``axial_from_mm`` to ``axial_to_mm`` (from the datum face). A defect counts in the
    zone its centre lies in; a kind the zone does not limit is judged by the surface's
    limits for the rest of the bore."""

    id: str = Field(pattern=HOLE_ID_PATTERN)
    axial_from_mm: float
    axial_to_mm: float

    @model_validator(mode="after")
    def _ordered(self) -> SurfaceZone:
        if not self.axial_from_mm < self.axial_to_mm:
            raise SpecProblems([(("axial_to_mm",), f"must be above axial_from_mm ({self.axial_from_mm:g})")])
        return self


class Surface(_SurfaceLimits):
    """The inner surface's criteria (issue 23; docs/part-specs.md, Surface): the band the
    coverage scan looks at (``axial_from_mm`` .. ``axial_to_mm``, default the whole
    bore), the limits elsewhere in it (``max_pore_mm``, ``max_scratch_mm``), the
    sealing ``zones`` with theirs, and at every compensating hole's rim the largest
    burr and chip (``max_burr_mm``, ``max_chip_mm``: length along the rim).
    ``every_part``: scan every part; false: only when the job asks (a sampling plan:
    the coverage scan costs a minute of machine time)."""

    every_part: bool = True
    axial_from_mm: float | None = None
    axial_to_mm: float | None = None
    max_burr_mm: float | None = None
    max_chip_mm: float | None = None
    zones: list[SurfaceZone] = Field(default_factory=list)

    @field_validator("max_burr_mm", "max_chip_mm")
    @classmethod
    def _positive_rim_limit(cls, v: float | None) -> float | None:
        if v is not None and not v > 0:
            raise ValueError(f"must be positive (got {v}); leave it out to set no limit")
        return v

    def limit(self, kind: str, zone: SurfaceZone | None) -> float | None:
        """The largest ``kind`` allowed in ``zone`` (None: elsewhere)."""
        key = f"max_{kind}_mm"
        if zone is not None and getattr(zone, key, None) is not None:
            return getattr(zone, key)
        return getattr(self, key, None)


@dataclass(frozen=True)
class Characteristic:
    """One measured characteristic with its limits, as the sequencer and store use it.

    ``id`` is ``<hole id>.<kind>`` (``hole_1.position``); limits are inclusive.
    """

    id: str
    hole_id: str
    kind: str
    unit: str
    nominal: float
    lower_limit: float
    upper_limit: float

    def conforms(self, measured: float) -> bool:
        """Plain acceptance, limits inclusive. No guard band for measurement
        uncertainty is applied: that decision rule belongs to the sequencer."""
        return self.lower_limit <= measured <= self.upper_limit


class PartSpec(_SpecModel):
    """A part spec file, validated."""

    part_number: str = Field(pattern=PART_NUMBER_PATTERN)
    description: str = ""
    unit: Literal["mm"] = "mm"
    bore: Bore
    placement: Placement = Field(default_factory=Placement)
    holes: list[Hole] = Field(min_length=1)
    #: the inner surface's criteria and coverage scan; None: the holes only
    surface: Surface | None = None

    @model_validator(mode="after")
    def _holes_fit_bore(self) -> PartSpec:
        problems: list[tuple[tuple, str]] = []
        seen: dict[str, int] = {}
        for i, h in enumerate(self.holes):
            if h.id in seen:
                problems.append((("holes", i, "id"), f"{h.id!r} is already the id of holes[{seen[h.id]}]"))
            seen.setdefault(h.id, i)
            if h.diameter.upper_limit >= self.bore.diameter_mm:
                problems.append((("holes", i, "diameter"),
                                 f"upper limit {h.diameter.upper_limit:g} mm is not smaller than the bore "
                                 f"({self.bore.diameter_mm:g} mm)"))
            radius_mm = h.diameter.upper_limit / 2.0
            lo, hi = h.position.lower_limit - radius_mm, h.position.upper_limit + radius_mm
            if lo < 0.0 or hi > self.bore.depth_mm:
                problems.append((("holes", i, "position"),
                                 f"the hole spans {lo:g}..{hi:g} mm along the axis, outside the bore "
                                 f"(0..{self.bore.depth_mm:g} mm deep)"))
        if self.surface is not None:
            problems.extend(self._surface_problems(seen))
        datum = self.placement.angular_datum
        if datum is not None and datum not in seen:
            problems.append((("placement", "angular_datum"),
                             f"{datum!r} is not a hole of this part (holes: {', '.join(seen)})"))
        if problems:
            raise SpecProblems(problems)
        return self

    def _surface_problems(self, hole_ids: dict[str, int]) -> list[tuple[tuple, str]]:
        sf = self.surface
        problems: list[tuple[tuple, str]] = []
        lo, hi = self.surface_band_mm()
        if not 0.0 <= lo < hi <= self.bore.depth_mm:
            problems.append((("surface", "axial_to_mm" if hi > self.bore.depth_mm or hi <= lo else "axial_from_mm"),
                             f"the band {lo:g}..{hi:g} mm must lie in the bore (0..{self.bore.depth_mm:g} mm) "
                             f"and not be empty"))
        if sf.max_burr_mm is not None or sf.max_chip_mm is not None:
            for i, h in enumerate(self.holes):
                r = h.diameter.upper_limit / 2.0
                if h.position.lower_limit - r < lo or h.position.upper_limit + r > hi:
                    problems.append((("surface", "axial_from_mm" if h.position.lower_limit - r < lo else "axial_to_mm"),
                                     f"the burr and chip limits apply at every hole's rim, but {h.id} "
                                     f"({h.position.lower_limit:g}..{h.position.upper_limit:g} mm) lies outside the "
                                     f"band scanned ({lo:g}..{hi:g} mm)"))
        ids: dict[str, int] = {}
        for i, z in enumerate(sf.zones):
            if z.id in ids:
                problems.append((("surface", "zones", i, "id"), f"{z.id!r} is already the id of zones[{ids[z.id]}]"))
            ids.setdefault(z.id, i)
            if z.id in hole_ids:
                problems.append((("surface", "zones", i, "id"), f"{z.id!r} is the id of a hole"))
            if z.axial_from_mm < lo or z.axial_to_mm > hi:
                problems.append((("surface", "zones", i), f"{z.axial_from_mm:g}..{z.axial_to_mm:g} mm is outside the "
                                                          f"band scanned ({lo:g}..{hi:g} mm)"))
            for j, other in enumerate(sf.zones[:i]):
                if z.axial_from_mm < other.axial_to_mm and other.axial_from_mm < z.axial_to_mm:
                    problems.append((("surface", "zones", i), f"overlaps zones[{j}] ({other.id})"))
        return problems

    def surface_band_mm(self) -> tuple[float, float]:
        """The band of the bore the coverage scan looks at (mm from the datum face)."""
        sf = self.surface
        lo = 0.0 if sf is None or sf.axial_from_mm is None else sf.axial_from_mm
        hi = self.bore.depth_mm if sf is None or sf.axial_to_mm is None else sf.axial_to_mm
        return lo, hi

    def surface_zone(self, axial_mm: float) -> SurfaceZone | None:
        """The surface zone a place along the bore is in (None: elsewhere or no surface)."""
        if self.surface is None:
            return None
        for z in self.surface.zones:
            if z.axial_from_mm <= axial_mm <= z.axial_to_mm:
                return z
        return None

    def surface_characteristics(self) -> tuple[Characteristic, ...]:
        """The surface's criteria as characteristics (the largest defect of a kind, in mm,
        against 0 .. its limit): ``surface.<kind>`` for the band outside the zones,
        ``surface.<zone>.<kind>`` per zone, ``<hole>.<burr|chip>`` at each hole's rim.
        Only the kinds the spec limits; none without a surface table."""
        sf = self.surface
        if sf is None:
            return ()
        out = []

        def add(cid: str, subject: str, kind: str, limit: float | None) -> None:
            if limit is not None:
                out.append(Characteristic(id=cid, hole_id=subject, kind=kind, unit=self.unit, nominal=0.0,
                                          lower_limit=0.0, upper_limit=float(limit)))

        for kind in SURFACE_WALL_KINDS:
            add(f"surface.{kind}", "surface", kind, getattr(sf, f"max_{kind}_mm"))
        for z in sf.zones:
            for kind in SURFACE_WALL_KINDS:
                if getattr(z, f"max_{kind}_mm") is not None:
                    add(f"surface.{z.id}.{kind}", z.id, kind, getattr(z, f"max_{kind}_mm"))
        for h in self.holes:
            for kind in SURFACE_RIM_KINDS:
                add(f"{h.id}.{kind}", h.id, kind, getattr(sf, f"max_{kind}_mm"))
        return tuple(out)

    def characteristics(self) -> tuple[Characteristic, ...]:
        """Every characteristic in file order: per hole, diameter then position."""
        out = []
        for h in self.holes:
            for kind in CHARACTERISTIC_KINDS:
                tol: Tolerance = getattr(h, kind)
                out.append(Characteristic(
                    id=f"{h.id}.{kind}", hole_id=h.id, kind=kind, unit=self.unit,
                    nominal=tol.nominal, lower_limit=tol.lower_limit, upper_limit=tol.upper_limit,
                ))
        return tuple(out)

    def characteristic(self, characteristic_id: str) -> Characteristic:
        """The characteristic of that id; KeyError naming the known ids otherwise."""
        for c in self.characteristics():
            if c.id == characteristic_id:
                return c
        known = ", ".join(c.id for c in self.characteristics())
        raise KeyError(f"{self.part_number} has no characteristic {characteristic_id!r} (known: {known})")

    def hole(self, hole_id: str) -> Hole:
        for h in self.holes:
            if h.id == hole_id:
                return h
        raise KeyError(f"{self.part_number} has no hole {hole_id!r}")

    def to_json(self) -> dict:
        """The spec as written, plus the derived characteristics (what `parts show --json` prints)."""
        data = self.model_dump(mode="json", exclude_none=True)
        data["characteristics"] = [
            {"id": c.id, "unit": c.unit, "nominal": c.nominal,
             "lower_limit": c.lower_limit, "upper_limit": c.upper_limit}
            for c in self.characteristics()
        ]
        return data


def is_part_number(text: str) -> bool:
    return re.fullmatch(PART_NUMBER_PATTERN, text) is not None
