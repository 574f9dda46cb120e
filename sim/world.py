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
from typing import Any, Callable

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
class World:
    model: StationModel = field(default_factory=load_model)
    part: PartTruth = STANDARD_SAMPLE
    temperature: Temperature = field(default_factory=Temperature)

    # -------------------------------------------------------------- per axis
    def z_offset_mm(self, motor_mm: float, direction: int, time_s: float) -> float:
        """Carriage minus motor position of Z: the positioning error motion EZZ."""
        curve = self.model._motions("Z").z
        return float(curve.evaluate([motor_mm], [direction], [time_s], self.temperature.at([time_s]))[0]) * 1e-3

    def c_offset_deg(self, motor_deg: float, direction: int, time_s: float) -> float:
        """Table minus motor angle of C: the angular positioning error ECC."""
        curve = self.model._motions("C").c
        return float(curve.evaluate([motor_deg], [direction], [time_s], self.temperature.at([time_s]))[0]) / 3600.0

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
        ax, an, r = self.true_points([z_mm], [c_deg], direction_z, direction_c, time_s)
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
        if "Z" in physics:
            physics["Z"].actual_offset = self.z_offset_mm
        if "C" in physics:
            physics["C"].actual_offset = self.c_offset_deg


def world_from_dict(data: dict[str, Any], source: str = "<dict>", base: Path | None = None) -> World:
    """Build a world from a scenario's ``[world]`` table (all keys optional):
    ``model`` (a station model TOML, relative to the scenario), ``[world.temperature]``
    (start_c, rise_c, tau_s) and ``[[world.holes]]`` (name, axial_mm, angle_deg, diameter_mm)."""
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
    return World(model, part, temperature)


def load_world(scenario_path: str | Path | None = None) -> World:
    """The world of a scenario file (its ``[world]`` table), or the default world."""
    if scenario_path is None:
        return World()
    p = Path(scenario_path)
    data = tomllib.loads(p.read_text())
    return world_from_dict(data.get("world", {}), str(p), p.parent)
