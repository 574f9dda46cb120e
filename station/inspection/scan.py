"""The compensated bore scan: a plan that finds and measures each compensating hole.

For each hole the plan:

1. asks the error model (inverse compensation) for the commanded (z, C) that puts
   the endoscope's detection point on each frame's place, and moves both axes there
   at once, at their limits, arriving from below and counter-clockwise (direction +1
   on both axes, the direction the compensation was solved for, so backlash is
   always taken up the same way: an axis already below its target goes straight
   there, one above it goes past and back);
2. search: frames covering the hole's search zone (docs/inspection.md, Identity),
   nearest the expected place first; with an angular datum, a survey round the
   bore at the datum hole's band first;
3. re-centres on the hole found (compensated again), so it is measured near the
   optical axis, away from the frame's edges and the lens's distortion;
4. measurement frames: for each, the grating's reading of Z and the vision result.

Where a hole is on the part (axial position) comes from three measurements:

    axial = target + (grating - predicted carriage) + (cy - y_px) * mm_per_px

``target`` is where compensation put the detection point; the grating's reading
minus the carriage position the model predicted for that command is what the
model did not know (repeatability, drift), and moves the detection point with it
along z; the vision result is the hole's offset from the detection point. The
frames are combined into a mean with an expanded uncertainty (k = 2).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Mapping

import numpy as np

from station.kinematics.inverse import compensate
from station.kinematics.model import StationModel
from station.motion import AxisLimits, move_time_s
from station.parts.spec import PartSpec
from station.sequencer import messages as m
from station.vision.defects import MIN_HOLE_DIAMETER_MM


@dataclass(frozen=True)
class HoleTarget:
    """A hole of the part spec as the plan looks for it.

    ``angle_deg`` is the drawing's angle from the part's angular datum. The search
    zone (docs/inspection.md, Identity): along the axis ``axial_lo_mm`` ..
    ``axial_hi_mm`` (the position limits widened by the part's axial placement
    uncertainty), round the bore ``angle_half_deg`` either side of the expected angle
    (the drawing's angular tolerance; the plan adds the placement's when a fixture,
    not a datum hole, sets the part's angle)."""

    name: str
    axial_mm: float
    angle_deg: float = 0.0
    diameter_mm: float = 0.7
    axial_lo_mm: float | None = None
    axial_hi_mm: float | None = None
    angle_half_deg: float = 25.0
    diameter_lo_mm: float = 0.0
    diameter_hi_mm: float = math.inf
    #: the position's tolerance limits (inside the zone); None: the nominal
    axial_lo_tol_mm: float | None = None
    axial_hi_tol_mm: float | None = None

    @property
    def zone_axial_mm(self) -> tuple[float, float]:
        lo = self.axial_mm - 0.5 if self.axial_lo_mm is None else self.axial_lo_mm
        hi = self.axial_mm + 0.5 if self.axial_hi_mm is None else self.axial_hi_mm
        return lo, hi


def hole_targets(part: PartSpec) -> list[HoleTarget]:
    """The spec's holes with their search zones: the position limits widened by the
    part's axial placement uncertainty, the drawing's angular band (docs/part-specs.md)."""
    pad_mm = part.placement.axial_mm
    return [HoleTarget(h.id, h.position.nominal, h.angle_deg, h.diameter.nominal,
                       axial_lo_mm=h.position.lower_limit - pad_mm, axial_hi_mm=h.position.upper_limit + pad_mm,
                       angle_half_deg=h.angle_search_deg,
                       diameter_lo_mm=h.diameter.lower_limit, diameter_hi_mm=h.diameter.upper_limit,
                       axial_lo_tol_mm=h.position.lower_limit, axial_hi_tol_mm=h.position.upper_limit)
            for h in part.holes]


@dataclass(frozen=True)
class CameraGeometry:
    """What the plan must know of the camera: scale at the wall and frame size."""

    mm_per_px: float
    width_px: int
    height_px: int
    bore_radius_mm: float
    #: standard uncertainty of the scale (relative), from the calibration
    scale_u_rel: float = 2e-4
    #: the camera's calibration (``station.vision.calibration.CameraCalibration``) when
    #: the station has one: the lens's distortion, for what is measured off the centre
    calibration: Any = field(default=None, compare=False, repr=False)

    @property
    def centre_px(self) -> tuple[float, float]:
        # pixel centres at integer coordinates (docs/vision.md): the middle of the frame
        return (self.width_px - 1) / 2.0, (self.height_px - 1) / 2.0


@dataclass(frozen=True)
class ScanSettings:
    frames_per_hole: int = 5
    settle_s: float = 0.05
    #: each axis approaches its target from below by this much (mm, deg)
    approach_z_mm: float = 0.5
    approach_c_deg: float = 0.5
    #: a hole is searched for only where it is seen whole in some frame with this much
    #: wall between its rim and the frame's edge (mm): the vision stage needs the rim
    #: whole and a few pixels of wall outside it (docs/vision.md); barrel distortion
    #: moves points towards the centre, so it never takes a rim out of the frame
    frame_clearance_mm: float = 0.2
    #: how far a hole's place in a search frame may be from where the re-centred
    #: measurement puts it (mm): the lens's barrel distortion, uncorrected in search
    #: frames, moves a point 2.7 % of its distance from the centre at the corner
    #: (sim/camera/twin.py ENDOSCOPE_LENS; about 0.2 mm there); candidates this close to
    #: a zone are measured before the zone decides
    search_position_u_mm: float = 0.25
    #: a detection below this confidence is not taken for a hole (the vision stage
    #: scores real whole holes >= 0.77 on the station envelope's dev frames, and 4 of 610
    #: below 0.3 on the wide envelope's 13-15 % grooves: docs/vision.md, Confidence)
    min_confidence: float = 0.3
    #: a dark disc smaller than this (mm) is a pore, not a hole (the surface
    #: inspection's rule, ``station.vision.defects.MIN_HOLE_DIAMETER_MM``): never taken
    #: for a spec hole nor reported as an unexpected one
    min_hole_mm: float = MIN_HOLE_DIAMETER_MM
    #: re-centre when the hole is further than this from the frame centre (px)
    recentre_px: float = 5.0
    #: standard uncertainty the model leaves at the detection point along the bore
    #: after compensation and the grating (um), Type B: what the grating cannot see,
    #: the axial datum (the chain's z offsets, calibrated on a master part to U = 0.6
    #: um, k = 2: 0.3) and C's axial motion and the tilts times their arms (0.15), in
    #: quadrature. The model was measured once; the world has moved on since within
    #: that (docs/world.md); the monitors watch for more
    model_u_um: float = 0.35
    #: what the station's own evidence shows it has not corrected at the detection point
    #: along the bore (um, a bound): a drift since the last master check, a scale its
    #: model has no term for. Known systematic errors left uncorrected are added to the
    #: expanded uncertainty linearly, not in quadrature (the "SUMU" practice for an
    #: uncorrected bias): U = 2 u + bound. Set per inspection by the session from the
    #: checks (station.monitor.evidence; docs/monitor.md); 0 when they show nothing
    #: beyond the model's stated uncertainty
    evidence_bound_um: float = 0.0
    #: the part's expansion the master checks show (ppm): a hole's axial place from the
    #: part's datum face is reported at 20 degC, ``a (1 - ppm 1e-6)`` (ISO 1), the master
    #: (of the parts' material, at their temperature) standing in for a thermometer.
    #: Approved as a change ``part.scale_ppm`` (station.monitor.proposals)
    part_scale_ppm: float = 0.0
    #: standard uncertainty of one hole's centre (along the axis, y) and diameter from
    #: the vision stage (px), the Type B part the frames' scatter cannot show: the camera
    #: stays put while it takes a hole's frames, so the wall texture that moves the
    #: measured rim is the same in all of them.  Normally the hole's own figures are the
    #: term (``y_u_px``, ``diameter_u_px`` of the vision stage, averaged over the hole's
    #: frames; docs/vision.md: +/- 2 u holds about 95 % of the errors on fresh frames).
    #: These fixed ones stand in where the vision stage gives none (the rays-only
    #: pipeline): about three and four times the medians of `station bench vision`
    #: (0.017 px for both), round and conservative
    vision_centre_u_px: float = 0.05
    vision_diameter_u_px: float = 0.07
    #: False runs the station as the paper's "before compensation": commands and the
    #: carriage prediction from the ideal model, the grating's reading taken as where
    #: the detection point is (what the grating cannot see stays in the result)
    compensated: bool = True
    #: False ignores the grating: the detection point is where the (compensated or
    #: ideal) model says the command put it. For studies of what the grating adds.
    use_grating: bool = True


@dataclass
class FrameObservation:
    axial_mm: float
    angle_deg: float
    diameter_mm: float
    x_px: float
    y_px: float
    diameter_px: float
    confidence: float
    grating_mm: float | None
    z_cmd_mm: float
    c_cmd_deg: float
    #: host time of the grating's reading (time.monotonic), None without a grating
    time_s: float | None = None
    #: the vision stage's standard uncertainties of this frame's diameter and of the
    #: hole's y (px, k = 1), None when it gives none
    diameter_u_px: float | None = None
    y_u_px: float | None = None
    #: where the station's model put the carriage for this frame's command (mm): the
    #: grating's reading minus it is what the model did not know (the monitors watch it)
    carriage_pred_mm: float | None = None
    #: the hole's edge profile width in this frame (``HoleMeasurement.edge_sigma_px``, px),
    #: None when the vision stage gives none: the camera's blur is read from it
    #: (``station.vision.defects.camera_blur_from_edge``) and given to the coverage
    #: scan's frames, most of which show no hole to read it from
    edge_sigma_px: float | None = None


@dataclass
class HoleResult:
    name: str
    found: bool
    position_mm: float = math.nan
    position_u_mm: float = math.nan  # expanded, k = 2
    diameter_mm: float = math.nan
    diameter_u_mm: float = math.nan
    angle_deg: float = math.nan
    frames: list[FrameObservation] = field(default_factory=list)
    crop: Any = None  # image crop around the hole (uint8), for the record
    reason: str = ""


def _crop(image: np.ndarray, x: float, y: float, d: float) -> np.ndarray:
    half = int(math.ceil(d)) + 4
    xi, yi = int(round(x)), int(round(y))
    return np.ascontiguousarray(image[max(0, yi - half): yi + half + 1, max(0, xi - half): xi + half + 1])


#: commanded positions closer than this (mm or deg) are the same command: far below
#: a drive's count (0.1 um, 0.0001 deg), so a no-move never sends a step backwards
SAME_POSITION = 1e-6


def approach(targets: dict[str, float], settings: ScanSettings, motion: Mapping[str, AxisLimits],
             axes_at: dict[str, float]):
    """Move the axes to ``targets`` at once, each arriving in the positive direction
    (backlash taken up the way compensation was solved for): straight there when the
    axis is below its target and got where it is moving positive (``axes_at``: where
    each axis so arrived, updated here; absent: not known), else to ``approach`` below
    it first.  Moves at the axes' limits (``motion``) when known.  Returns whether
    anything moved (a plan)."""
    by = {"Z": settings.approach_z_mm, "C": settings.approach_c_deg}
    legs: dict[str, list[float]] = {}
    for ax, q in targets.items():
        p = axes_at.get(ax)
        if p is not None and abs(q - p) <= SAME_POSITION:
            continue
        legs[ax] = [q] if p is not None and q > p else [q - by[ax], q]

    def kw(ax: str) -> dict:
        lim = motion.get(ax)
        return {} if lim is None else {"velocity": lim.velocity, "acceleration": lim.acceleration}

    def first_leg_s(ax: str) -> float:
        lim, p = motion.get(ax), axes_at.get(ax)
        return 0.0 if lim is None or p is None else move_time_s(legs[ax][0] - p, lim)

    for ax, leg in legs.items():
        yield m.Move(ax, leg[0], wait=False, **kw(ax))
    # the second legs in the order their first legs end, so neither axis idles long
    for ax in sorted((a for a in legs if len(legs[a]) > 1), key=first_leg_s):
        yield m.Wait((ax,))
        yield m.Move(ax, legs[ax][1], wait=False, **kw(ax))
    if legs:
        yield m.Wait(tuple(legs))
    for ax in legs:
        axes_at[ax] = targets[ax]
    return bool(legs)


def goto(model: StationModel, axial_mm: float, angle_deg: float, settings: ScanSettings,
         motion: Mapping[str, AxisLimits] | None = None, axes_at: dict[str, float] | None = None):
    """Move so the detection point is on (axial, angle), approaching from below on both
    axes (:func:`approach`), and let it settle. Returns (z_cmd, c_cmd, predicted
    carriage z) via the generator's return value."""
    sol = compensate(model, [axial_mm], [angle_deg], direction_z=+1, direction_c=+1)
    if not sol.converged[0]:
        raise ValueError(f"compensation did not converge for axial {axial_mm} mm, angle {angle_deg} deg")
    z_cmd, c_cmd = float(sol.z_mm[0]), float(sol.c_deg[0])
    moved = yield from approach({"C": c_cmd, "Z": z_cmd}, settings, motion or {}, {} if axes_at is None else axes_at)
    if moved:
        yield m.Settle(settings.settle_s)
    return z_cmd, c_cmd, predicted_carriage_mm(model, z_cmd, +1)


def predicted_carriage_mm(model: StationModel, z_cmd_mm: float, direction: int = +1) -> float:
    """Where the station's model puts Z's carriage for the command ``z_cmd_mm`` reached
    moving in ``direction`` (+1 up, -1 down): the command plus the model's positioning
    error motion EZZ there. The grating's reading minus this is what the model did not
    know (the scans' drift term, the monitors' evidence, the station's own check of Z)."""
    ezz_um = model.motions_of("Z").z.evaluate([z_cmd_mm], direction=[direction])[0]
    return float(z_cmd_mm + ezz_um * 1e-3)


def combine(result: HoleResult, geo: CameraGeometry, settings: ScanSettings) -> None:
    """Mean over frames and expanded uncertainty (k = 2) per GUM: Type A from the
    scatter of the frames (standard error of the mean), Type B from the scale
    calibration (relative, times the hole's size or offset), the model's residual
    and the vision stage's error common to the hole's frames.

    The vision terms are the hole's own: the mean of its frames' ``y_u_px`` (position)
    and ``diameter_u_px`` when every frame has one, else the fixed
    ``ScanSettings.vision_centre_u_px`` and ``vision_diameter_u_px``.  They are not
    divided by the number of frames (the texture that makes most of them is the same in
    every frame of the hole), and the sensor noise they also hold is counted again in
    the frames' scatter: conservative by that much."""
    ax = np.array([f.axial_mm for f in result.frames])
    dia = np.array([f.diameter_mm for f in result.frames])
    n = len(ax)
    s_ax = ax.std(ddof=1) / math.sqrt(n) if n > 1 else 0.0
    s_dia = dia.std(ddof=1) / math.sqrt(n) if n > 1 else 0.0
    cy = geo.centre_px[1]
    offset_mm = abs(np.mean([(cy - f.y_px) * geo.mm_per_px for f in result.frames]))
    u_vis_c = vision_u_px([f.y_u_px for f in result.frames], settings.vision_centre_u_px) * geo.mm_per_px
    u_vis_d = vision_u_px([f.diameter_u_px for f in result.frames], settings.vision_diameter_u_px) * geo.mm_per_px
    u_ax = math.sqrt(s_ax**2 + (geo.scale_u_rel * offset_mm) ** 2 + (settings.model_u_um * 1e-3) ** 2 + u_vis_c**2)
    u_dia = math.sqrt(s_dia**2 + (geo.scale_u_rel * float(dia.mean())) ** 2 + u_vis_d**2)
    result.position_mm = float(ax.mean()) * (1.0 - settings.part_scale_ppm * 1e-6)
    result.position_u_mm = 2.0 * u_ax + settings.evidence_bound_um * 1e-3
    result.diameter_mm = float(dia.mean())
    result.diameter_u_mm = 2.0 * u_dia
    result.angle_deg = float(np.mean([f.angle_deg for f in result.frames]))


def vision_u_px(per_frame: list[float | None], fixed_px: float) -> float:
    """The vision stage's standard uncertainty of one of a hole's values (px): the mean
    of its frames' own figures, or the fixed Type B term when any frame lacks one."""
    if per_frame and all(u is not None and math.isfinite(u) and u > 0 for u in per_frame):
        return float(np.mean(per_frame))
    return fixed_px


# ---------------------------------------------------------------------------------
# Identity: which physical hole is which spec hole (docs/inspection.md, Identity)


def wrap_deg(a: float) -> float:
    """An angle difference in [-180, 180)."""
    return (a + 180.0) % 360.0 - 180.0


def fmt_deg(a: float, digits: int = 2) -> str:
    """An angle in [-180, 180) for a person (no "-0.00")."""
    return f"{round(wrap_deg(a), digits) + 0.0:.{digits}f}"


@dataclass(frozen=True)
class SearchZone:
    """Where on the part a spec hole may be: an axial band and an angular band about
    ``angle_deg`` (table frame); ``angle_half_deg`` >= 180 is the whole turn."""

    axial_lo_mm: float
    axial_hi_mm: float
    angle_deg: float
    angle_half_deg: float

    @property
    def all_round(self) -> bool:
        return self.angle_half_deg >= 180.0

    def contains(self, axial_mm: float, angle_deg: float, radius_mm: float, margin_mm: float = 0.0) -> bool:
        if not self.axial_lo_mm - margin_mm <= axial_mm <= self.axial_hi_mm + margin_mm:
            return False
        if self.all_round:
            return True
        return abs(wrap_deg(angle_deg - self.angle_deg)) <= self.angle_half_deg + math.degrees(margin_mm / radius_mm)

    def describe(self) -> str:
        ang = "all round" if self.all_round else f"angle {fmt_deg(self.angle_deg)} +/- {self.angle_half_deg:.2f} deg"
        return f"axial {self.axial_lo_mm:.3f}..{self.axial_hi_mm:.3f} mm, {ang}"


@dataclass(eq=False)
class Sighting:
    """A whole hole seen in a frame, placed on the part from the frame's target
    (no grating, no distortion correction: good to ``search_position_u_mm``)."""

    axial_mm: float
    angle_deg: float
    diameter_mm: float
    confidence: float
    #: set once a re-centred measurement of this hole exists
    measured: HoleResult | None = None

    @property
    def place(self) -> tuple[float, float]:
        if self.measured is not None and self.measured.found:
            return self.measured.position_mm, self.measured.angle_deg
        return self.axial_mm, self.angle_deg


@dataclass
class ScanFinding:
    """Something the scan saw that the spec does not expect, or could not resolve."""

    kind: str  # unexpected_hole | ambiguous_identity | datum
    message: str
    subject: str | None = None
    axial_mm: float | None = None
    angle_deg: float | None = None
    diameter_mm: float | None = None
    u_mm: float | None = None


@dataclass
class ScanResult:
    """The plan's return value: every spec hole's result (spec order of the targets
    given), the findings, and the part's angular datum on the table (deg; None when a
    fixture sets the part's angle)."""

    holes: list[HoleResult]
    findings: list[ScanFinding] = field(default_factory=list)
    datum_deg: float | None = None
    frames: int = 0
    #: the coverage scan's result when the surface was scanned (station.inspection.surface)
    surface: Any = None


@dataclass
class _Frame:
    """A search or measurement frame: where it looked (part) and was commanded (axes)."""

    axial_mm: float
    angle_deg: float
    z_cmd_mm: float
    c_cmd_deg: float


class _BoreScan:
    """The plan's state: where the axes are, what has been seen and assigned."""

    def __init__(self, model: StationModel, targets: list[HoleTarget], geo: CameraGeometry, settings: ScanSettings,
                 datum: str | None, placement_angle_deg: float, motion: Mapping[str, AxisLimits] | None = None):
        self.model = model
        self.motion = dict(motion or {})
        #: where each axis arrived moving positive in this plan (approach's bookkeeping)
        self.axes_at: dict[str, float] = {}
        self.targets = targets
        self.geo = geo
        self.settings = settings
        self.datum = datum
        self.placement_angle_deg = placement_angle_deg
        self.radius_mm = geo.bore_radius_mm
        self.sightings: list[Sighting] = []
        self.frames: list[_Frame] = []
        self.assigned: dict[str, Sighting] = {}
        self.findings: list[ScanFinding] = []
        self.offset_deg = 0.0  # the part's angular datum on the table
        self.c_now_deg = 0.0
        self.here: tuple | None = None  # (target, z_cmd, c_cmd, carriage_pred) of the last goto
        d_max = max((t.diameter_hi_mm if math.isfinite(t.diameter_hi_mm) else 2 * t.diameter_mm) for t in targets)
        # half the wall a frame shows where a hole's centre is seen whole, with clearance
        self.usable_half_u_mm = geo.width_px * geo.mm_per_px / 2 - d_max / 2 - settings.frame_clearance_mm
        self.usable_half_v_mm = geo.height_px * geo.mm_per_px / 2 - d_max / 2 - settings.frame_clearance_mm
        if self.usable_half_u_mm <= 0 or self.usable_half_v_mm <= 0:
            raise ValueError(f"a hole of {d_max:.3f} mm does not fit a frame of "
                             f"{geo.width_px * geo.mm_per_px:.2f} x {geo.height_px * geo.mm_per_px:.2f} mm")
        self.progress_done = 0

    # -------------------------------------------------------------- geometry
    def wall_mm(self, a: tuple[float, float], b: tuple[float, float]) -> float:
        """Distance on the unrolled bore wall between two (axial, angle) places."""
        return math.hypot(a[0] - b[0], math.radians(wrap_deg(a[1] - b[1])) * self.radius_mm)

    def expected(self, t: HoleTarget, offset_deg: float | None = None) -> tuple[float, float]:
        off = self.offset_deg if offset_deg is None else offset_deg
        return t.axial_mm, (t.angle_deg + off) % 360.0

    def zone(self, t: HoleTarget, offset_deg: float | None = None) -> SearchZone:
        lo, hi = t.zone_axial_mm
        half = t.angle_half_deg + (self.placement_angle_deg if self.datum is None else 0.0)
        return SearchZone(lo, hi, self.expected(t, offset_deg)[1], half)

    def nearest_spec_hole(self, place: tuple[float, float], offset_deg: float | None = None) -> HoleTarget:
        return min(self.targets, key=lambda t: self.wall_mm(place, self.expected(t, offset_deg)))

    def admissible(self, t: HoleTarget, place: tuple[float, float], offset_deg: float | None = None,
                   margin_mm: float = 0.0) -> bool:
        """Inside ``t``'s zone and nearer its expected place than any other spec hole's."""
        if not self.zone(t, offset_deg).contains(place[0], place[1], self.radius_mm, margin_mm):
            return False
        return self.nearest_spec_hole(place, offset_deg) is t

    def covered(self, place: tuple[float, float]) -> bool:
        """Whether some frame so far would have shown a hole at ``place`` whole."""
        for f in self.frames:
            du = math.radians(wrap_deg(place[1] - f.angle_deg)) * self.radius_mm
            if abs(place[0] - f.axial_mm) <= self.usable_half_v_mm and abs(du) <= self.usable_half_u_mm:
                return True
        return False

    def frames_for(self, zone: SearchZone, expected: tuple[float, float]) -> list[tuple[float, float]]:
        """Frame centres (axial, angle) such that a hole anywhere in ``zone`` is seen
        whole, with clearance, in at least one: rows along the axis, columns round it."""
        extent_v = zone.axial_hi_mm - zone.axial_lo_mm
        rows = max(1, math.ceil(extent_v / (2 * self.usable_half_v_mm)))
        axials = [zone.axial_lo_mm + (i + 0.5) * extent_v / rows for i in range(rows)]
        if zone.all_round:
            cols = max(1, math.ceil(2 * math.pi * self.radius_mm / (2 * self.usable_half_u_mm)))
            # round the turn from where the table is, always forward
            start = self.c_now_deg % 360.0
            angles = [(start + j * 360.0 / cols) % 360.0 for j in range(cols)]
            return [(a, g) for g in angles for a in axials]
        extent_u = 2 * math.radians(zone.angle_half_deg) * self.radius_mm
        cols = max(1, math.ceil(extent_u / (2 * self.usable_half_u_mm)))
        lo = zone.angle_deg - zone.angle_half_deg
        angles = [lo + (j + 0.5) * 2 * zone.angle_half_deg / cols for j in range(cols)]
        pts = [(a, g % 360.0) for a in axials for g in angles]
        return sorted(pts, key=lambda p: self.wall_mm(p, expected))

    # -------------------------------------------------------------- motion and frames
    def goto(self, axial_mm: float, angle_deg: float):
        """Move the detection point to (axial, angle); the table goes the short way round
        (an endless axis: the command is the angle's turn nearest the present one)."""
        angle_cmd = self.c_now_deg + wrap_deg(angle_deg - self.c_now_deg)
        z_cmd, c_cmd, carriage = yield from goto(self.model, axial_mm, angle_cmd, self.settings, self.motion,
                                                 self.axes_at)
        self.c_now_deg = c_cmd
        self.here = ((axial_mm, angle_deg % 360.0), z_cmd, c_cmd, carriage)
        return z_cmd, c_cmd, carriage

    def sight(self, target: tuple[float, float], holes) -> list[Sighting]:
        """Whole, confident detections of a frame placed on the part; each joins the
        sighting of the same physical hole seen before (within a diameter) or is new."""
        cx, cy = self.geo.centre_px
        s = self.geo.mm_per_px
        out = []
        for h in holes or []:
            if getattr(h, "partial", False) or getattr(h, "confidence", 1.0) < self.settings.min_confidence \
                    or h.diameter_px * s < self.settings.min_hole_mm:
                continue
            axial = target[0] + (cy - h.y_px) * s
            angle = (target[1] + math.degrees((h.x_px - cx) * s / self.radius_mm)) % 360.0
            d = h.diameter_px * s
            same = [o for o in self.sightings
                    if self.wall_mm(o.place, (axial, angle)) < max(d, o.diameter_mm, 2 * self.settings.search_position_u_mm)]
            if same:
                out.append(same[0])
                continue
            new = Sighting(axial, angle, d, float(getattr(h, "confidence", 1.0)))
            self.sightings.append(new)
            out.append(new)
        return out

    def look(self, place: tuple[float, float], label: str):
        """One search frame centred on ``place``."""
        z_cmd, c_cmd, _ = yield from self.goto(*place)
        self.frames.append(_Frame(place[0], place[1] % 360.0, z_cmd, c_cmd))
        yield m.Checkpoint(f"{label} search")
        frame = yield m.Capture()
        holes = yield m.Measure(frame.image)
        return self.sight(place, holes)

    def looked_over(self, frames: list[_Frame]) -> str:
        if not frames:
            return "no frame"
        z = [f.z_cmd_mm for f in frames]
        c = [f.c_cmd_deg for f in frames]
        return (f"{len(frames)} frame{'s' if len(frames) > 1 else ''} at Z {min(z):.3f}..{max(z):.3f} mm, "
                f"C {min(c):.3f}..{max(c):.3f} deg")

    # -------------------------------------------------------------- the plan
    def run(self):
        results: dict[str, HoleResult] = {}
        datum_deg = None
        # the table is endless: its turns so far decide the short way to each angle
        c_now = yield m.ReadAxis("C")
        if isinstance(c_now, (int, float)) and math.isfinite(c_now):
            self.c_now_deg = float(c_now)
        if self.datum is not None:
            ok = yield from self.locate_datum(results)
            if not ok:
                return self.finish(results, None)
            datum_deg = self.offset_deg
        for t in sorted(self.targets, key=lambda t: t.axial_mm):
            if t.name not in results:
                results[t.name] = yield from self.find(t)
            yield m.Checkpoint(f"{t.name} done")
        return self.finish(results, datum_deg)

    def finish(self, results: dict[str, HoleResult], datum_deg: float | None) -> ScanResult:
        for t in self.targets:
            if t.name not in results:
                results[t.name] = HoleResult(t.name, False, reason=f"{t.name} not searched: the part's angle is unknown")
        assigned = list(self.assigned.values())
        for sg in self.sightings:
            if any(sg is a or self.wall_mm(sg.place, a.place) < max(sg.diameter_mm, a.diameter_mm) for a in assigned):
                continue
            ax, an = sg.place
            near = self.nearest_spec_hole((ax, an))
            where = f"{ax:.3f} mm, {an:.2f} deg"
            r = sg.measured if sg.measured is not None and sg.measured.found else None
            d = r.diameter_mm if r is not None else sg.diameter_mm
            self.findings.append(ScanFinding(
                "unexpected_hole",
                f"unexpected hole of {d:.3f} mm at {where} on the table"
                + ("" if datum_deg is None else f" ({fmt_deg(an - datum_deg)} deg from the datum)")
                + f", nearest spec hole {near.name}",
                subject=None, axial_mm=ax, angle_deg=an, diameter_mm=d,
                u_mm=r.position_u_mm if r is not None else 2 * self.settings.search_position_u_mm))
        return ScanResult([results[t.name] for t in self.targets], self.findings, datum_deg,
                          sum(1 for _ in self.frames))

    def find(self, t: HoleTarget):
        """Search ``t``'s zone, measure its candidates, and decide."""
        zone = self.zone(t)
        expected = self.expected(t)
        yield m.Note(f"{t.name}: search zone {zone.describe()}")
        first = len(self.frames)
        for place in self.frames_for(zone, expected):
            yield from self.look(place, t.name)
        frames = self.frames[first:]
        u = self.settings.search_position_u_mm
        cands = [sg for sg in self.sightings
                 if all(sg is not a for a in self.assigned.values()) and self.admissible(t, sg.place, margin_mm=u)]
        return (yield from self.decide(t, cands, zone, frames))

    def decide(self, t: HoleTarget, cands: list[Sighting], zone: SearchZone, frames: list[_Frame],
               offset_deg: float | None = None):
        """Measure the candidates (re-centred) and apply the identity rules."""
        looked = f"searched {zone.describe()} ({self.looked_over(frames)})"
        expected = self.expected(t, offset_deg)
        for sg in sorted(cands, key=lambda sg: self.wall_mm(sg.place, expected)):
            if sg.measured is None:
                sg.measured = yield from self.measure_at(t, sg)
        inside = [sg for sg in cands if sg.measured is not None and sg.measured.found
                  and self.admissible(t, sg.place, offset_deg)]
        # several in the zone: the one the drawing allows (position within its limits,
        # then diameter within its limits), if exactly one is; else nobody knows
        tol_lo = t.axial_mm if t.axial_lo_tol_mm is None else t.axial_lo_tol_mm
        tol_hi = t.axial_mm if t.axial_hi_tol_mm is None else t.axial_hi_tol_mm
        for allowed in (lambda sg: tol_lo <= sg.measured.position_mm <= tol_hi,
                        lambda sg: t.diameter_lo_mm <= sg.measured.diameter_mm <= t.diameter_hi_mm):
            if len(inside) > 1:
                fits = [sg for sg in inside if allowed(sg)]
                if len(fits) == 1:
                    inside = fits
        if not inside:
            seen = [sg for sg in cands if sg.measured is not None and sg.measured.found]
            extra = ("; the nearest hole seen is at " + ", ".join(f"{sg.place[0]:.3f} mm, {sg.place[1]:.2f} deg" for sg in seen[:1])
                     + ", outside the zone") if seen else ""
            return HoleResult(t.name, False, reason=f"{t.name} not found: {looked}{extra}")
        if len(inside) > 1:
            places = "; ".join(f"{sg.place[0]:.3f} mm, {sg.place[1]:.2f} deg, {sg.measured.diameter_mm:.3f} mm"
                               for sg in inside)
            msg = f"{t.name}: {len(inside)} holes in its search zone ({places}): which is {t.name} is not known"
            self.findings.append(ScanFinding("ambiguous_identity", msg, subject=t.name))
            return HoleResult(t.name, False, reason=msg)
        sg = inside[0]
        self.assigned[t.name] = sg
        r = sg.measured
        r.name = t.name
        return r

    def measure_at(self, t: HoleTarget, sg: Sighting):
        """Re-centre on a sighting and take the measurement frames."""
        settings, geo = self.settings, self.geo
        cx, cy = geo.centre_px
        s = geo.mm_per_px
        target = (sg.axial_mm, sg.angle_deg)
        here = self.here
        if here is not None and self.wall_mm(here[0], target) <= settings.recentre_px * s:
            target, z_cmd, c_cmd, carriage_pred = here
        else:
            z_cmd, c_cmd, carriage_pred = yield from self.goto(*target)
        yield m.Checkpoint(f"{t.name} measure")
        result = HoleResult(t.name, True)
        accept_px = max(0.6 * sg.diameter_mm / s, 2 * settings.search_position_u_mm / s)
        total = len(self.targets) * settings.frames_per_hole
        for k in range(settings.frames_per_hole):
            reading = yield m.ReadEncoder()
            frame = yield m.Capture()
            holes = yield m.Measure(frame.image)
            self.progress_done = min(self.progress_done + 1, total)
            yield m.Progress(self.progress_done, total, f"{t.name} frame {k + 1}")
            whole = [h for h in holes or [] if not getattr(h, "partial", False)
                     and getattr(h, "confidence", 1.0) >= settings.min_confidence
                     and h.diameter_px * s >= settings.min_hole_mm]
            near = [h for h in whole if math.hypot(h.x_px - cx, h.y_px - cy) <= accept_px]
            h = min(near, key=lambda h: math.hypot(h.x_px - cx, h.y_px - cy)) if near else None
            others = [o for o in whole if o is not h]
            if others:
                self.sight(target, others)
            if h is None:
                yield m.Note(f"{t.name}: frame {k + 1} shows no whole hole at the centre; skipped")
                continue
            grating = None if reading is None else float(reading.position_mm)
            drift = 0.0 if grating is None or not settings.use_grating else grating - carriage_pred
            axial = target[0] + drift + (cy - h.y_px) * s
            # unwrapped about the target (frames of a hole at 0 deg must not average to 180)
            angle = target[1] + math.degrees((h.x_px - cx) * s / self.radius_mm)
            obs = FrameObservation(axial, angle, h.diameter_px * s, h.x_px, h.y_px, h.diameter_px,
                                   float(getattr(h, "confidence", 1.0)), grating, z_cmd, c_cmd,
                                   None if reading is None else float(reading.timestamp),
                                   getattr(h, "diameter_u_px", None), getattr(h, "y_u_px", None), carriage_pred,
                                   getattr(h, "edge_sigma_px", None))
            result.frames.append(obs)
            yield m.Emit("frame", (t.name, len(result.frames) - 1, obs))
            if result.crop is None:
                result.crop = _crop(frame.image, h.x_px, h.y_px, h.diameter_px)
        if not result.frames:
            return HoleResult(t.name, False, reason=f"{t.name} lost during the measurement frames")
        combine(result, geo, settings)
        result.angle_deg %= 360.0
        return result

    def locate_datum(self, results: dict[str, HoleResult]):
        """Find the part's angle: survey the datum hole's axial band all round, take the
        hole there as the datum (a hole of another spec hole's band when the datum hole
        is not found), and measure it. Several holes in the band: the hypothesis under
        which the other spec holes are where the drawing puts them wins; a tie is
        ambiguous and ends the search."""
        by_name = {t.name: t for t in self.targets}
        first = by_name[self.datum]
        chain = [first] + [t for t in sorted(self.targets, key=lambda t: t.axial_mm) if t is not first]
        tried = []
        for dh in chain:
            lo, hi = dh.zone_axial_mm
            band = SearchZone(lo, hi, 0.0, 180.0)
            yield m.Note(f"angular datum: survey round the bore for {dh.name} ({band.describe()})")
            f0 = len(self.frames)
            for place in self.frames_for(band, (dh.axial_mm, 0.0)):
                yield from self.look(place, f"{dh.name} survey")
            frames = self.frames[f0:]
            u = self.settings.search_position_u_mm
            cands = [sg for sg in self.sightings if all(sg is not a for a in self.assigned.values())
                     and band.contains(sg.axial_mm, sg.angle_deg, self.radius_mm, u)]
            tried.append(f"{dh.name}: {band.describe()} ({self.looked_over(frames)}), {len(cands)} hole(s)")
            if not cands:
                results[dh.name] = HoleResult(dh.name, False, reason=f"{dh.name} not found: searched {band.describe()} "
                                                                     f"({self.looked_over(frames)})")
                continue
            chosen = yield from self.choose_datum(dh, cands)
            if chosen is None:
                msg = (f"angular datum not known: {len(cands)} holes in {dh.name}'s band "
                       f"({'; '.join(f'{sg.axial_mm:.3f} mm, {sg.angle_deg:.2f} deg' for sg in cands)}) "
                       f"and the other holes do not tell which is {dh.name}")
                self.findings.append(ScanFinding("ambiguous_identity", msg, subject=dh.name))
                for t in self.targets:
                    results.setdefault(t.name, HoleResult(t.name, False, reason=msg))
                return False
            off = wrap_deg(chosen.angle_deg - dh.angle_deg)
            r = yield from self.decide(dh, [chosen], self.zone(dh, off), frames, offset_deg=off)
            if not r.found:
                results[dh.name] = r
                continue
            self.offset_deg = wrap_deg(r.angle_deg - dh.angle_deg) % 360.0
            results[dh.name] = r
            how = "" if dh is first else f" ({first.name}, the datum hole, was not found)"
            self.findings.append(ScanFinding(
                "datum", f"part's angular datum {fmt_deg(self.offset_deg, 3)} deg on the table, set by {dh.name}{how}; "
                         f"survey: {self.looked_over(frames)}",
                subject=dh.name, axial_mm=r.position_mm, angle_deg=r.angle_deg, diameter_mm=r.diameter_mm,
                u_mm=r.position_u_mm))
            return True
        msg = "angular datum not found: no hole in " + "; ".join(tried)
        for t in self.targets:
            results.setdefault(t.name, HoleResult(t.name, False, reason=msg))
        return False

    def choose_datum(self, dh: HoleTarget, cands: list[Sighting]):
        """The sighting that is ``dh`` under the hypothesis the other holes best confirm."""
        if len(cands) == 1:
            return cands[0]

        def score(sg: Sighting) -> tuple[int, int, float]:
            """(holes confirmed, -holes absent where looked, -misfit): the misfit, the
            wall distance of the confirming holes from their drawing places, counts
            only in whole mm (finer is the search frames' own error)."""
            off = wrap_deg(sg.angle_deg - dh.angle_deg)
            confirmed = contradicted = 0
            misfit_mm = 0.0
            u = self.settings.search_position_u_mm
            for t in self.targets:
                if t is dh:
                    continue
                near = [o for o in self.sightings if o is not sg and self.admissible(t, o.place, off, u)]
                if near:
                    confirmed += 1
                    misfit_mm += min(self.wall_mm(o.place, self.expected(t, off)) for o in near)
                elif self.covered(self.expected(t, off)):
                    contradicted += 1
            return confirmed, -contradicted, -float(math.floor(misfit_mm))

        for _ in range(2):
            scores = {id(sg): score(sg) for sg in cands}
            best = max(scores.values())
            top = [sg for sg in cands if scores[id(sg)] == best]
            if len(top) == 1:
                return top[0]
            # look where the tied hypotheses put the other holes, then score again
            unseen = [(sg, t) for sg in top for t in self.targets
                      if t is not dh and not self.covered(self.expected(t, wrap_deg(sg.angle_deg - dh.angle_deg)))]
            if not unseen:
                break
            for sg, t in unseen:
                place = self.expected(t, wrap_deg(sg.angle_deg - dh.angle_deg))
                if not self.covered(place):
                    yield from self.look(place, f"{dh.name} datum check")
        fits = [sg for sg in top if dh.diameter_lo_mm <= sg.diameter_mm <= dh.diameter_hi_mm]
        return fits[0] if len(fits) == 1 else None


def bore_scan(model: StationModel, holes: list[HoleTarget], geo: CameraGeometry, settings: ScanSettings | None = None,
              *, datum: str | None = None, placement_angle_deg: float = 0.0,
              motion: Mapping[str, AxisLimits] | None = None):
    """The whole scan (a plan; returns a :class:`ScanResult`): the angular datum first
    when the part has one (``datum``: the hole that sets it), then every hole in order
    of axial position. ``placement_angle_deg``: the part's angular placement
    uncertainty on a fixture, added to each hole's angular zone when no datum hole
    sets the angle. ``motion``: the axes' limits ("Z", "C"), at which the plan moves
    (the drives' defaults when absent)."""
    settings = settings or ScanSettings()
    if not settings.compensated:
        model = model.without_errors()
    if datum is not None and datum not in {t.name for t in holes}:
        raise ValueError(f"angular datum {datum!r} is not one of the holes")
    return (yield from _BoreScan(model, list(holes), geo, settings, datum, placement_angle_deg, motion).run())
