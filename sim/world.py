"""The simulated world: the true state of the station that the twins report.

The drives' physics (``sim.servo``) know only the motor positions. The world adds
what the machine really does, from the *same* error model that compensation
inverts (``station.kinematics``):

* the carriage of Z is at ``z + EZZ(z, direction, t, T)`` (what the grating reads);
* the table is at ``C + ECC(C, direction, t, T)``;
* the endoscope's detection point sits on the part where the full model (13 error
  motions, installation errors, alignment, vocabulary effects) puts it: this is
  what the camera twin looks at.

Temperature is a function of time (constant, or a warm-up towards a final value),
because the thermal effects of the vocabulary need it.

The world's model is its own, never the station's (docs/world.md): the scenario names
it, and the drift physics of ``sim.drift`` (the screw's heat, the shop's air, wear, a
collision) move the machine on from it as a real one moves on from its last laser
measurement.
"""

from __future__ import annotations

import math
import tomllib
from dataclasses import dataclass, field, fields, replace
from pathlib import Path
from typing import Any

import numpy as np

from sim.camera.render import HONING_ANGLE_DEG
from sim.drift import SIX_DOF_KEYS, Drift, drift_from_dict
from station.effects import Eccentricity
from station.kinematics.model import StationModel, load_model
from station.kinematics.parameters import SixDof


@dataclass(frozen=True)
class HoleTruth:
    """A compensating hole as it really is on the part (ground truth)."""

    name: str
    axial_mm: float
    angle_deg: float
    diameter_mm: float


@dataclass(frozen=True)
class SurfaceDefect:
    """A surface defect as it really is on the bore wall (ground truth; issue 23).

    Pores and scratches sit at ``axial_mm`` / ``angle_deg`` (the centroid of their area);
    ``orientation_deg`` is the direction of their length on the unrolled wall, from the
    circumferential direction (increasing angle) towards increasing axial position.
    Burrs and chips sit on the rim of the hole named ``hole``, ``at_deg`` round it (the
    same sense on the unrolled wall); their length is along the rim, their width the
    mean height into (burr) or depth out of (chip) the hole. ``reflectance``: share of
    the wall's level (None: the kind's default, ``sim.camera.defects``); ``seed``: the
    irregular outline. Sizes in mm.
    """

    name: str
    kind: str
    length_mm: float
    width_mm: float
    axial_mm: float = 0.0
    angle_deg: float = 0.0
    orientation_deg: float = 0.0
    hole: str | None = None
    at_deg: float = 0.0
    reflectance: float | None = None
    seed: int = 0


@dataclass(frozen=True)
class PartTruth:
    part_number: str = "ZDZG-22.2-12.3851"
    bore_diameter_mm: float = 22.2
    holes: tuple[HoleTruth, ...] = ()
    defects: tuple[SurfaceDefect, ...] = ()
    #: which casting this is: the camera twin draws the honed wall's texture from it and
    #: the place in view, so two parts differ in their grooves, grain and blotches where
    #: they are drawn alike (0: the scenario's one part, as before parts had one)
    texture_seed: int = 0
    #: the honing cross-hatch's half-angle (deg from the circumferential direction, both
    #: signs): the part's, as its honing machine was set (plateau honing 20-35, helical
    #: slide honing 60-75); the camera twin draws the grooves at it
    hatch_deg: float = HONING_ANGLE_DEG


#: the paper's standard sample (Table 4): both holes 0.7 mm, at 71.03 and 85.19 mm.
#: The angles are not in the paper; the holes of a master cylinder lie on one line.
STANDARD_SAMPLE = PartTruth(
    holes=(HoleTruth("hole_1", 71.03, 0.0, 0.700), HoleTruth("hole_2", 85.19, 0.0, 0.700)),
)


@dataclass
class Temperature:
    """Machine temperature over time: ``start + rise * (1 - exp(-t / tau))`` degC."""

    start_c: float = 20.0
    rise_c: float = 0.0
    tau_s: float = 1800.0

    def at(self, time_s) -> np.ndarray:
        t = np.asarray(time_s, dtype=float)
        if self.rise_c == 0.0:
            return np.full_like(t, self.start_c)
        return self.start_c + self.rise_c * (1.0 - np.exp(-t / self.tau_s))


@dataclass(frozen=True)
class TruePoint:
    """Where the detection point really is on the part."""

    axial_mm: float
    angle_deg: float
    radius_mm: float
    z_motor_mm: float
    c_motor_deg: float
    time_s: float


@dataclass
class Repeatability:
    """Random error of each approach (ISO 230-2's s): one normal draw per move,
    held until the next move starts. Z in um, C in arcsec."""

    z_um: float = 0.0
    c_arcsec: float = 0.0
    seed: int = 0


@dataclass
class World:
    model: StationModel = field(default_factory=load_model)
    part: PartTruth = STANDARD_SAMPLE
    temperature: Temperature = field(default_factory=Temperature)
    repeatability: Repeatability = field(default_factory=Repeatability)
    drift: Drift = field(default_factory=Drift)
    #: the camera's sensor flaws (``sim.camera.sensor.SensorFlaws``: hot and dim pixels,
    #: a trap in a column); None: a flawless sensor
    camera_sensor: Any = None

    def __post_init__(self):
        self._rng = np.random.default_rng(self.repeatability.seed)
        #: the present approach's random error of each axis (mm, deg)
        self._approach_error = {"Z": 0.0, "C": 0.0}
        #: each axis' last target (the drift's screw heating and wear count the travel)
        self._last_target: dict[str, float | None] = {"Z": None, "C": None}
        self._effective: tuple[tuple, StationModel] | None = None
        body = self.drift.collision.body
        try:
            self.model.topology.by_name(body)
        except KeyError:
            raise ValueError(f"world.collision: body {body!r} is not a body of the model's topology") from None

    # -------------------------------------------------------------- drift
    def effective_model(self, time_s: float) -> StationModel:
        """The world's model as the drift has left it at ``time_s``: C's runout grown by
        wear, a collision's step of installation errors."""
        runout_um = round(self.drift.wear.runout_extra_um(), 4)
        collided = self.drift.collision.happened(time_s)
        key = (runout_um, collided, id(self.model))
        if self._effective is not None and self._effective[0] == key:
            return self._effective[1]
        model = self.model
        if runout_um:
            mc = model.motions_of("C")
            # a grown radial runout of the table's bearing, as the model's own eccentricity
            mc = replace(mc, x=mc.x.with_effects(Eccentricity(amplitude=runout_um, phase=0.0)),
                         y=mc.y.with_effects(Eccentricity(amplitude=runout_um, phase=math.pi / 2)))
            model = replace(model, motions={**model.motions, "C": mc})
        if collided:
            c = self.drift.collision
            old = model.static_errors.get(c.body, SixDof())
            new = SixDof(**{k: getattr(old, k) + c.shift.get(k, 0.0) for k in SIX_DOF_KEYS})
            model = replace(model, static_errors={**model.static_errors, c.body: new})
        self._effective = (key, model)
        return model

    def carriage_drift_mm(self, motor_mm: float, direction: int, time_s: float) -> float:
        """Where the drift carries Z's carriage beyond the model (mm): the warm screw's
        growth and the lost motion wear added (half of it each way, as backlash)."""
        um = self.drift.screw.growth_um(motor_mm, time_s) + direction * self.drift.wear.backlash_extra_um() / 2.0
        return um * 1e-3

    def on_move(self, axis: str, target: float, time_s: float) -> None:
        """A move started: the screw takes its heat, wear counts its travel, the
        repeatability draws the approach's error."""
        last = self._last_target.get(axis)
        if last is not None:
            if axis == "Z":
                self.drift.screw.on_move(target - last, time_s)
            self.drift.wear.on_move(axis, target - last)
        self._last_target[axis] = target
        self.new_approach(axis)

    def grating_reading_mm(self, carriage_mm: float, time_s: float) -> float:
        """What the grating reads with the carriage truly at ``carriage_mm``."""
        return carriage_mm + self.drift.ambient.grating_error_um(carriage_mm, time_s) * 1e-3

    def approach_error(self, axis: str) -> float:
        """The present approach's random error of ``axis`` (mm for Z, deg for C)."""
        return self._approach_error[axis]

    def new_approach(self, axis: str) -> None:
        """A move started on ``axis``: draw its repeatability error."""
        sigma = self.repeatability.z_um * 1e-3 if axis == "Z" else self.repeatability.c_arcsec / 3600.0
        self._approach_error[axis] = float(self._rng.normal(0.0, sigma)) if sigma > 0 else 0.0

    # -------------------------------------------------------------- per axis
    def z_offset_mm(self, motor_mm: float, direction: int, time_s: float) -> float:
        """Carriage minus motor position of Z: the positioning error motion EZZ."""
        curve = self.model.motions_of("Z").z
        deviation_um = curve.evaluate([motor_mm], [direction], [time_s], self.temperature.at([time_s]))[0]
        return float(deviation_um) * 1e-3 + self._approach_error["Z"] + self.carriage_drift_mm(motor_mm, direction,
                                                                                                time_s)

    def c_offset_deg(self, motor_deg: float, direction: int, time_s: float) -> float:
        """Table minus motor angle of C: the angular positioning error ECC."""
        curve = self.model.motions_of("C").c
        deviation_arcsec = curve.evaluate([motor_deg], [direction], [time_s], self.temperature.at([time_s]))[0]
        return float(deviation_arcsec) / 3600.0 + self._approach_error["C"]

    # -------------------------------------------------------------- the detection point
    def true_points(self, z_mm, c_deg, direction_z=0, direction_c=0, time_s=0.0):
        """(axial mm, angle deg, radius mm) of the detection point at motor poses, vectorised:
        the model (as the drift has left it at the first time given) and the frame's growth."""
        z = np.atleast_1d(np.asarray(z_mm, dtype=float))
        t = np.broadcast_to(np.asarray(time_s, dtype=float), z.shape)
        model = self.effective_model(float(t.flat[0]) if t.size else 0.0)
        e = model.errors(
            z, c_deg, direction_z=direction_z, direction_c=direction_c, time_s=t, temperature_c=self.temperature.at(t)
        )
        axial, angle, radius = model.part_coordinates(e.actual_point_mm)
        frame_mm = np.array([self.drift.ambient.frame_shift_um(float(ti)) for ti in t.flat]).reshape(t.shape) * 1e-3
        return axial + frame_mm, angle, radius

    def true_point(self, z_mm: float, c_deg: float, direction_z: int = 0, direction_c: int = 0, time_s: float = 0.0) -> TruePoint:
        """The detection point with the drives at motor poses ``z_mm``, ``c_deg`` now.

        The present approach's random errors (``Repeatability``) move the carriage and the
        table as the grating sees them (``z_offset_mm``, ``c_offset_deg``), so they move
        the detection point and the part with them: they enter here as a displacement of
        each axis along itself.  (Evaluating the error curves 0.3 um further along shifts
        them by their slope times that, far below a nanometre.)  ``true_points`` is the
        model alone, for any poses, without them.
        """
        z_eff = z_mm + self._approach_error["Z"] + self.carriage_drift_mm(z_mm, direction_z, time_s)
        c_eff = c_deg + self._approach_error["C"]
        ax, an, r = self.true_points([z_eff], [c_eff], direction_z, direction_c, time_s)
        return TruePoint(float(ax[0]), float(an[0]), float(r[0]), z_mm, c_deg, time_s)

    def holes_near(self, point: TruePoint, half_width_mm: float, half_height_mm: float):
        """Holes in a window around the point, as (hole, tangential mm, axial mm)
        offsets from it, on the unrolled bore wall (tangential = arc length)."""
        scale = self.drift.ambient.part_scale(point.time_s)  # the part at its temperature
        r = self.part.bore_diameter_mm / 2.0 * scale
        out = []
        for h in self.part.holes:
            dphi = (h.angle_deg - point.angle_deg + 180.0) % 360.0 - 180.0
            du = math.radians(dphi) * r
            dv = h.axial_mm * scale - point.axial_mm
            if abs(du) <= half_width_mm + h.diameter_mm and abs(dv) <= half_height_mm + h.diameter_mm:
                out.append((h, du, dv))
        return out

    def defects_near(self, point: TruePoint, half_width_mm: float, half_height_mm: float):
        """Pores and scratches in a window around the point, as (defect, tangential mm,
        axial mm) offsets from it, as ``holes_near`` places the holes (rim defects go
        with their holes)."""
        scale = self.drift.ambient.part_scale(point.time_s)
        r = self.part.bore_diameter_mm / 2.0 * scale
        out = []
        for d in self.part.defects:
            if d.hole is not None:
                continue
            du = math.radians((d.angle_deg - point.angle_deg + 180.0) % 360.0 - 180.0) * r
            dv = d.axial_mm * scale - point.axial_mm
            if abs(du) <= half_width_mm + d.length_mm and abs(dv) <= half_height_mm + d.length_mm:
                out.append((d, du, dv))
        return out

    # -------------------------------------------------------------- wiring
    def attach(self, twins: Any) -> None:
        """Plug into a running ``sim.twins.TwinStation``: the drives' carriages move
        with the error model, and the grating reads the true carriage."""
        physics = twins.physics
        for axis, hook in (("Z", self.z_offset_mm), ("C", self.c_offset_deg)):
            if axis in physics:
                physics[axis].actual_offset = hook
                physics[axis].move_listeners.append(lambda target, direction, t, axis=axis: self.on_move(axis, target, t))
        encoder = getattr(twins, "encoder", None)
        if encoder is not None and "Z" in physics:
            z = physics["Z"]

            def reading_mm() -> float:
                t = z.now()
                return self.grating_reading_mm(z.carriage_position(t), t)

            encoder.position_mm = reading_mm


def world_from_dict(data: dict[str, Any], source: str = "<dict>", base: Path | None = None) -> World:
    """Build a world from a scenario's ``[world]`` table (all keys optional):
    ``model`` (a model TOML, relative to the scenario; default: the station's shipped
    model, a world that agrees with it), ``[world.temperature]`` (start_c, rise_c,
    tau_s), ``[world.repeatability]`` (z_um, c_arcsec, seed), the drift physics
    (``[world.screw_heating]``, ``[world.ambient]``, ``[world.wear]``,
    ``[world.collision]``: sim.drift), ``[[world.holes]]`` (name, axial_mm,
    angle_deg, diameter_mm), ``[[world.defects]]`` (``SurfaceDefect``'s fields) and
    ``texture_seed`` and ``hatch_deg`` (``PartTruth``'s), ``[world.camera_sensor]``
    (``sim.camera.sensor.SensorFlaws``'s fields: the camera's flawed pixels)."""
    model_path = data.get("model")
    if model_path is not None:
        p = Path(model_path)
        if not p.is_absolute():
            # beside the scenario; else one of the shipped scenarios' models (a copy of
            # the default scenario elsewhere keeps naming "default_world.toml")
            shipped = Path(__file__).with_name("scenarios") / p
            here = base / p if base is not None else p
            if not here.is_file() and shipped.is_file():
                here = shipped
            elif not here.is_file():
                raise ValueError(f"{source}: [world] model {model_path!r}: no such file beside the scenario "
                                 f"({here}) nor among the shipped scenarios ({shipped})")
            p = here
        model = load_model(p)
    else:
        model = load_model()
    temp = data.get("temperature", {})
    unknown = set(temp) - {"start_c", "rise_c", "tau_s"}
    if unknown:
        raise ValueError(f"{source}: [world.temperature] unknown keys {sorted(unknown)}")
    temperature = Temperature(**{k: float(v) for k, v in temp.items()})
    rep = data.get("repeatability", {})
    unknown = set(rep) - {"z_um", "c_arcsec", "seed"}
    if unknown:
        raise ValueError(f"{source}: [world.repeatability] unknown keys {sorted(unknown)}")
    repeatability = Repeatability(float(rep.get("z_um", 0.0)), float(rep.get("c_arcsec", 0.0)), int(rep.get("seed", 0)))
    holes = STANDARD_SAMPLE.holes
    if "holes" in data:
        holes = []
        for i, h in enumerate(data["holes"]):
            try:
                holes.append(HoleTruth(str(h["name"]), float(h["axial_mm"]), float(h.get("angle_deg", 0.0)), float(h["diameter_mm"])))
            except KeyError as exc:
                raise ValueError(f"{source}: world.holes[{i}] lacks {exc.args[0]!r}") from None
        holes = tuple(holes)
    defects = []
    names = {h.name for h in holes}
    for i, d in enumerate(data.get("defects", [])):
        try:
            extra = set(d) - {f.name for f in fields(SurfaceDefect)}
            if extra:
                raise ValueError(f"unknown keys {sorted(extra)}")
            defect = SurfaceDefect(**{k: v for k, v in d.items()})
        except (TypeError, ValueError) as exc:
            raise ValueError(f"{source}: world.defects[{i}]: {exc}") from None
        from sim.camera.defects import KINDS, RIM_KINDS

        if defect.kind not in KINDS:
            raise ValueError(f"{source}: world.defects[{i}]: kind {defect.kind!r} is not one of {', '.join(KINDS)}")
        if (defect.kind in RIM_KINDS) != (defect.hole is not None):
            raise ValueError(f"{source}: world.defects[{i}]: burrs and chips name their hole, pores and scratches none")
        if defect.hole is not None and defect.hole not in names:
            raise ValueError(f"{source}: world.defects[{i}]: no hole named {defect.hole!r}")
        defects.append(defect)
    texture_seed = data.get("texture_seed", 0)
    if isinstance(texture_seed, bool) or not isinstance(texture_seed, int) or texture_seed < 0:
        raise ValueError(f"{source}: world.texture_seed must be a whole number >= 0, not {texture_seed!r}")
    hatch = data.get("hatch_deg", PartTruth.hatch_deg)
    if isinstance(hatch, bool) or not isinstance(hatch, (int, float)) or not 0.0 < hatch < 90.0:
        raise ValueError(f"{source}: world.hatch_deg must be a half-angle in degrees between 0 and 90 (exclusive), "
                         f"not {hatch!r}")
    sensor = None
    if "camera_sensor" in data:
        from sim.camera.sensor import SensorFlaws

        table = data["camera_sensor"]
        known = {f.name for f in fields(SensorFlaws)}
        if not isinstance(table, dict) or set(table) - known:
            raise ValueError(f"{source}: [world.camera_sensor] takes only {sorted(known)}, not "
                             f"{sorted(set(table) - known) if isinstance(table, dict) else table!r}")
        try:
            sensor = SensorFlaws(**table)
        except (TypeError, ValueError) as exc:
            raise ValueError(f"{source}: [world.camera_sensor]: {exc}") from None
    part = PartTruth(str(data.get("part_number", STANDARD_SAMPLE.part_number)),
                     float(data.get("bore_diameter_mm", STANDARD_SAMPLE.bore_diameter_mm)), holes, tuple(defects),
                     texture_seed, float(hatch))
    try:
        return World(model, part, temperature, repeatability, drift_from_dict(data, source), sensor)
    except ValueError as exc:
        msg = str(exc)
        raise ValueError(msg if msg.startswith(source) else f"{source}: {msg}") from None


def load_world(scenario_path: str | Path | None = None) -> World:
    """The world of a scenario file (its ``[world]`` table); the default scenario's
    when none is named."""
    if scenario_path is None:
        from sim.twins import DEFAULT_SCENARIO

        scenario_path = DEFAULT_SCENARIO
    p = Path(scenario_path)
    data = tomllib.loads(p.read_text(encoding="utf-8-sig"))
    return world_from_dict(data.get("world", {}), str(p), p.parent)


def defect_truth_place(part: PartTruth, d: SurfaceDefect) -> tuple[float, float]:
    """Where a defect's centroid really is on the part (axial mm, angle deg): pores and
    scratches where they are given; a burr half its height inside its hole's rim, a chip
    half its depth outside, ``at_deg`` round the hole (0: towards increasing angle, 90:
    towards increasing axial position, on the unrolled wall)."""
    if d.hole is None:
        return d.axial_mm, d.angle_deg % 360.0
    h = next(h for h in part.holes if h.name == d.hole)
    r = h.diameter_mm / 2.0 + (-d.width_mm / 2.0 if d.kind == "burr" else d.width_mm / 2.0)
    du = r * math.cos(math.radians(d.at_deg))
    dv = r * math.sin(math.radians(d.at_deg))
    return h.axial_mm + dv, (h.angle_deg + math.degrees(du / (part.bore_diameter_mm / 2.0))) % 360.0


def rendered_size(part: PartTruth, d: SurfaceDefect, mm_per_px: float = 0.01) -> tuple[float, float]:
    """A defect's length and width as the camera twin really renders it (its outline's
    greatest Feret diameter and the extent across, a rim defect's arc and mean height):
    a pore's given width is only approximate (its ragged outline is scaled to its
    length), so the truth a measurement is scored against is the outline's own."""
    from sim.camera.defects import DefectSpec, geometry
    from sim.camera.render import HoleSpec

    s = mm_per_px
    if d.hole is None:
        spec = DefectSpec(d.kind, 0.0, 0.0, d.length_mm / s, d.width_mm / s, -d.orientation_deg, d.reflectance,
                          None, d.seed)
        holes = []
    else:
        h = next(h for h in part.holes if h.name == d.hole)
        holes = [HoleSpec(0.0, 0.0, h.diameter_mm / s)]
        spec = DefectSpec(d.kind, 0.0, 0.0, d.length_mm / s, d.width_mm / s, -d.at_deg, d.reflectance, 0, d.seed)
    t = geometry(spec, holes).truth().with_scale(s)
    return float(t.length_mm), float(t.width_mm)


def scratch_middle(part: PartTruth, d: SurfaceDefect, mm_per_px: float = 0.01) -> tuple[float, float]:
    """Where the middle of a scratch's centre line lies on the part (axial mm, angle deg),
    as the twin renders it bent: the station places a scratch there (a long one's area
    centroid, the truth's ``axial_mm`` / ``angle_deg``, is moved along it by its width's
    variation, ~0.05 mm on a 15 mm scratch)."""
    from sim.camera.defects import DefectSpec, geometry

    s = mm_per_px
    spec = DefectSpec(d.kind, 0.0, 0.0, d.length_mm / s, d.width_mm / s, -d.orientation_deg, d.reflectance, None,
                      d.seed)
    x, y = geometry(spec, []).scratch_middle_px()  # ideal px from the centroid: +x round, +y against the axis
    r = part.bore_diameter_mm / 2.0
    return d.axial_mm - y * s, (d.angle_deg + math.degrees(x * s / r)) % 360.0


def match_defects(world: "World", found) -> list[tuple[Any, dict | None]]:
    """Each defect the station reports (``axial_mm``, ``angle_deg``, ``kind``,
    ``length_mm``) with the world's defect it is (ground truth: an annotation for tests
    and benches): the nearest true defect of the same family (wall: pore, scratch; rim:
    burr, chip) whose centroid lies within half its length (at least 0.3 mm) of the
    report, each true defect taken at most once; None when there is none. A scratch's
    also says how far the report lies from its centre line's middle (``middle_error_mm``,
    :func:`scratch_middle`), where the station places a scratch."""
    part = world.part
    r = part.bore_diameter_mm / 2.0
    truths = [(t, defect_truth_place(part, t)) for t in part.defects]
    rim = {"burr", "chip"}
    pairs = []
    for i, d in enumerate(found):
        for j, (t, (ax, an)) in enumerate(truths):
            if (d.kind in rim) != (t.kind in rim):
                continue
            dist = math.hypot(d.axial_mm - ax, math.radians((d.angle_deg - an + 180.0) % 360.0 - 180.0) * r)
            if dist <= max(0.3, t.length_mm / 2.0):
                pairs.append((dist, i, j))
    taken_i, taken_j, out = set(), set(), {}
    for dist, i, j in sorted(pairs):
        if i in taken_i or j in taken_j:
            continue
        taken_i.add(i)
        taken_j.add(j)
        t, (ax, an) = truths[j]
        length, width = rendered_size(part, t)
        out[i] = {"name": t.name, "kind": t.kind, "axial_mm": round(ax, 5), "angle_deg": round(an, 5),
                  "length_mm": round(length, 5), "width_mm": round(width, 5), "place_error_mm": round(dist, 5)}
        if t.kind == "scratch":  # where the station places a scratch: its centre line's middle
            d = found[i]
            mx, mn = scratch_middle(part, t)
            off = math.radians((d.angle_deg - mn + 180.0) % 360.0 - 180.0) * r
            out[i]["middle_error_mm"] = round(math.hypot(d.axial_mm - mx, off), 5)
    return [(d, out.get(i)) for i, d in enumerate(found)]
