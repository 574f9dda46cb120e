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
"""

from __future__ import annotations

import math
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from station.kinematics.model import StationModel, load_model


@dataclass(frozen=True)
class HoleTruth:
    """A compensating hole as it really is on the part (ground truth)."""

    name: str
    axial_mm: float
    angle_deg: float
    diameter_mm: float


@dataclass(frozen=True)
class PartTruth:
    part_number: str = "ZDZG-22.2-12.3851"
    bore_diameter_mm: float = 22.2
    holes: tuple[HoleTruth, ...] = ()


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

    def __post_init__(self):
        self._rng = np.random.default_rng(self.repeatability.seed)
        #: the present approach's random error of each axis (mm, deg)
        self._approach_error = {"Z": 0.0, "C": 0.0}

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
        return float(deviation_um) * 1e-3 + self._approach_error["Z"]

    def c_offset_deg(self, motor_deg: float, direction: int, time_s: float) -> float:
        """Table minus motor angle of C: the angular positioning error ECC."""
        curve = self.model.motions_of("C").c
        deviation_arcsec = curve.evaluate([motor_deg], [direction], [time_s], self.temperature.at([time_s]))[0]
        return float(deviation_arcsec) / 3600.0 + self._approach_error["C"]

    # -------------------------------------------------------------- the detection point
    def true_points(self, z_mm, c_deg, direction_z=0, direction_c=0, time_s=0.0):
        """(axial mm, angle deg, radius mm) of the detection point at motor poses, vectorised."""
        z = np.atleast_1d(np.asarray(z_mm, dtype=float))
        t = np.broadcast_to(np.asarray(time_s, dtype=float), z.shape)
        e = self.model.errors(
            z, c_deg, direction_z=direction_z, direction_c=direction_c, time_s=t, temperature_c=self.temperature.at(t)
        )
        return self.model.part_coordinates(e.actual_point_mm)

    def true_point(self, z_mm: float, c_deg: float, direction_z: int = 0, direction_c: int = 0, time_s: float = 0.0) -> TruePoint:
        """The detection point with the drives at motor poses ``z_mm``, ``c_deg`` now.

        The present approach's random errors (``Repeatability``) move the carriage and the
        table as the grating sees them (``z_offset_mm``, ``c_offset_deg``), so they move
        the detection point and the part with them: they enter here as a displacement of
        each axis along itself.  (Evaluating the error curves 0.3 um further along shifts
        them by their slope times that, far below a nanometre.)  ``true_points`` is the
        model alone, for any poses, without them.
        """
        z_eff = z_mm + self._approach_error["Z"]
        c_eff = c_deg + self._approach_error["C"]
        ax, an, r = self.true_points([z_eff], [c_eff], direction_z, direction_c, time_s)
        return TruePoint(float(ax[0]), float(an[0]), float(r[0]), z_mm, c_deg, time_s)

    def holes_near(self, point: TruePoint, half_width_mm: float, half_height_mm: float):
        """Holes in a window around the point, as (hole, tangential mm, axial mm)
        offsets from it, on the unrolled bore wall (tangential = arc length)."""
        r = self.part.bore_diameter_mm / 2.0
        out = []
        for h in self.part.holes:
            dphi = (h.angle_deg - point.angle_deg + 180.0) % 360.0 - 180.0
            du = math.radians(dphi) * r
            dv = h.axial_mm - point.axial_mm
            if abs(du) <= half_width_mm + h.diameter_mm and abs(dv) <= half_height_mm + h.diameter_mm:
                out.append((h, du, dv))
        return out

    # -------------------------------------------------------------- wiring
    def attach(self, twins: Any) -> None:
        """Plug into a running ``sim.twins.TwinStation``: the drives' carriages move
        with the error model, and the grating reads the true carriage."""
        physics = twins.physics
        for axis, hook in (("Z", self.z_offset_mm), ("C", self.c_offset_deg)):
            if axis in physics:
                physics[axis].actual_offset = hook
                physics[axis].move_listeners.append(lambda target, direction, t, axis=axis: self.new_approach(axis))


def world_from_dict(data: dict[str, Any], source: str = "<dict>", base: Path | None = None) -> World:
    """Build a world from a scenario's ``[world]`` table (all keys optional):
    ``model`` (a station model TOML, relative to the scenario), ``[world.temperature]``
    (start_c, rise_c, tau_s), ``[world.repeatability]`` (z_um, c_arcsec, seed) and
    ``[[world.holes]]`` (name, axial_mm, angle_deg, diameter_mm)."""
    model_path = data.get("model")
    if model_path is not None:
        p = Path(model_path)
        if not p.is_absolute() and base is not None:
            p = base / p
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
    part = PartTruth(str(data.get("part_number", STANDARD_SAMPLE.part_number)),
                     float(data.get("bore_diameter_mm", STANDARD_SAMPLE.bore_diameter_mm)), holes)
    return World(model, part, temperature, repeatability)


def load_world(scenario_path: str | Path | None = None) -> World:
    """The world of a scenario file (its ``[world]`` table); the default scenario's
    when none is named."""
    if scenario_path is None:
        from sim.twins import DEFAULT_SCENARIO

        scenario_path = DEFAULT_SCENARIO
    p = Path(scenario_path)
    data = tomllib.loads(p.read_text(encoding="utf-8-sig"))
    return world_from_dict(data.get("world", {}), str(p), p.parent)
