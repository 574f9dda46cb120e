"""The compensated bore scan: a plan that finds and measures each compensating hole.

For each hole the plan:

1. asks the error model (inverse compensation) for the commanded (z, C) that puts
   the endoscope's detection point on the hole's nominal place, and approaches it
   from below and counter-clockwise (direction +1 on both axes, the direction the
   compensation was solved for, so backlash is always taken up the same way);
2. coarse search: a frame there; if the hole is not in it, frames at offsets of
   most of a field of view around the nominal place, nearest first;
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
from typing import Any, Generator

import numpy as np

from station.kinematics.inverse import compensate
from station.kinematics.model import StationModel
from station.sequencer import messages as m


@dataclass(frozen=True)
class HoleTarget:
    name: str
    axial_mm: float
    angle_deg: float = 0.0
    diameter_mm: float = 0.7


@dataclass(frozen=True)
class CameraGeometry:
    """What the plan must know of the camera: scale at the wall and frame size."""

    mm_per_px: float
    width_px: int
    height_px: int
    bore_radius_mm: float
    #: standard uncertainty of the scale (relative), from the calibration
    scale_u_rel: float = 2e-4

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
    #: search offsets in fields of view (0.6: neighbouring frames overlap by 40 %)
    search_step_fov: float = 0.6
    search_rings: int = 2
    #: a detection below this confidence is not taken for a hole (the vision stage
    #: scores real whole holes >= 0.77 on the station envelope's dev frames, and 4 of 610
    #: below 0.3 on the wide envelope's 13-15 % grooves: docs/vision.md, Confidence)
    min_confidence: float = 0.3
    #: re-centre when the hole is further than this from the frame centre (px)
    recentre_px: float = 5.0
    #: standard uncertainty the model leaves after compensation (um): Type B, from
    #: the ISO 230-2 residual of the compensated axis; the default station's twin is
    #: its own model, so it is the grating's resolution (0.05 um) rounded up
    model_u_um: float = 0.1
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


def _best_hole(holes, geo: CameraGeometry, settings: ScanSettings):
    """The whole hole nearest to the frame centre, or None."""
    cx, cy = geo.centre_px
    good = [h for h in holes if not getattr(h, "partial", False) and getattr(h, "confidence", 1.0) >= settings.min_confidence]
    if not good:
        return None
    return min(good, key=lambda h: (h.x_px - cx) ** 2 + (h.y_px - cy) ** 2)


def _offsets_mm(geo: CameraGeometry, settings: ScanSettings) -> list[tuple[float, float]]:
    """Search offsets (axial mm, tangential mm) in rings around the nominal place, nearest first."""
    step_v = settings.search_step_fov * geo.height_px * geo.mm_per_px
    step_u = settings.search_step_fov * geo.width_px * geo.mm_per_px
    out = [(0.0, 0.0)]
    for ring in range(1, settings.search_rings + 1):
        ring_pts = [(i * step_v, j * step_u) for i in range(-ring, ring + 1) for j in range(-ring, ring + 1)
                    if max(abs(i), abs(j)) == ring]
        out += sorted(ring_pts, key=lambda p: math.hypot(*p))
    return out


def _crop(image: np.ndarray, x: float, y: float, d: float) -> np.ndarray:
    half = int(math.ceil(d)) + 4
    xi, yi = int(round(x)), int(round(y))
    return np.ascontiguousarray(image[max(0, yi - half): yi + half + 1, max(0, xi - half): xi + half + 1])


def goto(model: StationModel, axial_mm: float, angle_deg: float, settings: ScanSettings):
    """Move so the detection point is on (axial, angle), approaching from below on both axes.
    Returns (z_cmd, c_cmd, predicted carriage z) via the generator's return value."""
    sol = compensate(model, [axial_mm], [angle_deg], direction_z=+1, direction_c=+1)
    if not sol.converged[0]:
        raise ValueError(f"compensation did not converge for axial {axial_mm} mm, angle {angle_deg} deg")
    z_cmd, c_cmd = float(sol.z_mm[0]), float(sol.c_deg[0])
    yield m.Move("C", c_cmd - settings.approach_c_deg)
    yield m.Move("C", c_cmd)
    yield m.Move("Z", z_cmd - settings.approach_z_mm)
    yield m.Move("Z", z_cmd)
    yield m.Settle(settings.settle_s)
    ezz_um = model.motions_of("Z").z.evaluate([z_cmd], direction=[1])[0]
    return z_cmd, c_cmd, z_cmd + ezz_um * 1e-3


def measure_hole(model: StationModel, hole: HoleTarget, geo: CameraGeometry, settings: ScanSettings,
                 step: int = 0, total: int = 1) -> Generator[m.Msg, Any, HoleResult]:
    """The plan for one hole (see the module docstring)."""
    cx, cy = geo.centre_px
    s = geo.mm_per_px
    rad_per_mm = 1.0 / geo.bore_radius_mm
    found = None
    target = (hole.axial_mm, hole.angle_deg)
    yield m.Note(f"{hole.name}: coarse search around {hole.axial_mm:.3f} mm, {hole.angle_deg:.3f} deg")
    for dv, du in _offsets_mm(geo, settings):
        target = (hole.axial_mm + dv, hole.angle_deg + math.degrees(du * rad_per_mm))
        yield from goto(model, *target, settings)
        yield m.Checkpoint(f"{hole.name} search")
        frame = yield m.Capture()
        holes = yield m.Measure(frame.image)
        found = _best_hole(holes, geo, settings)
        if found is not None:
            break
    if found is None:
        return HoleResult(hole.name, False, reason=f"{hole.name} not found within {settings.search_rings} search rings")
    # re-centre on it
    off_v = (cy - found.y_px) * s
    off_u = (found.x_px - cx) * s
    if math.hypot(found.x_px - cx, found.y_px - cy) > settings.recentre_px:
        target = (target[0] + off_v, target[1] + math.degrees(off_u * rad_per_mm))
    z_cmd, c_cmd, carriage_pred = yield from goto(model, *target, settings)
    yield m.Checkpoint(f"{hole.name} measure")
    result = HoleResult(hole.name, True)
    for k in range(settings.frames_per_hole):
        reading = yield m.ReadEncoder()
        frame = yield m.Capture()
        holes = yield m.Measure(frame.image)
        h = _best_hole(holes, geo, settings)
        yield m.Progress(step * settings.frames_per_hole + k + 1, total * settings.frames_per_hole, f"{hole.name} frame {k + 1}")
        if h is None:
            yield m.Note(f"{hole.name}: frame {k + 1} shows no whole hole; skipped")
            continue
        grating = None if reading is None else float(reading.position_mm)
        drift = 0.0 if grating is None or not settings.use_grating else grating - carriage_pred
        axial = target[0] + drift + (cy - h.y_px) * s
        angle = target[1] + math.degrees((h.x_px - cx) * s * rad_per_mm)
        result.frames.append(FrameObservation(axial, angle, h.diameter_px * s, h.x_px, h.y_px, h.diameter_px,
                                              float(getattr(h, "confidence", 1.0)), grating, z_cmd, c_cmd,
                                              None if reading is None else float(reading.timestamp),
                                              getattr(h, "diameter_u_px", None), getattr(h, "y_u_px", None)))
        if result.crop is None:
            result.crop = _crop(frame.image, h.x_px, h.y_px, h.diameter_px)
    if not result.frames:
        return HoleResult(hole.name, False, reason=f"{hole.name} lost during the measurement frames")
    combine(result, geo, settings)
    return result


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
    result.position_mm = float(ax.mean())
    result.position_u_mm = 2.0 * u_ax
    result.diameter_mm = float(dia.mean())
    result.diameter_u_mm = 2.0 * u_dia
    result.angle_deg = float(np.mean([f.angle_deg for f in result.frames]))


def vision_u_px(per_frame: list[float | None], fixed_px: float) -> float:
    """The vision stage's standard uncertainty of one of a hole's values (px): the mean
    of its frames' own figures, or the fixed Type B term when any frame lacks one."""
    if per_frame and all(u is not None and math.isfinite(u) and u > 0 for u in per_frame):
        return float(np.mean(per_frame))
    return fixed_px


def bore_scan(model: StationModel, holes: list[HoleTarget], geo: CameraGeometry, settings: ScanSettings | None = None):
    """The whole scan: every hole in order of axial position (one pass up the bore)."""
    settings = settings or ScanSettings()
    if not settings.compensated:
        model = model.without_errors()
    ordered = sorted(holes, key=lambda h: h.axial_mm)
    results = []
    for i, hole in enumerate(ordered):
        r = yield from measure_hole(model, hole, geo, settings, i, len(ordered))
        results.append(r)
        yield m.Checkpoint(f"{hole.name} done")
    return results
