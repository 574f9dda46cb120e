"""Random worlds that differ from the station's model by realistic amounts.

A station's model is what a laser campaign (and a master, for the datum) measured of the
machine once; the machine differs from it by that campaign's own uncertainty and by
what has happened since. ``draw_world_model`` makes such a machine from any model: the
model plus, per error motion, a smooth random departure the size of the instrument's
expanded uncertainty that measured it, tabulated on a grid finer than any
calibration's nodes (5 mm on Z, 10 deg on C), with a short-wave part the campaign's
targets could not resolve; every installation error moved by the uncertainty of its
own measurement; the vocabulary's effects of the model kept with their parameters moved
(wear of the screw's nut and of the table's bearing), and a screw-lead error (a
periodic of EZZ with the lead's period) that no model of the station has.

``write_world_scenario`` writes the world as a model file and a scenario naming it (the
default scenario's drives, drift and part, its repeatability seeded from the world's),
for ``station ... --scenario`` and ``open_session(scenario=...)``: the twin runs the drawn
world, the station keeps its own model. The truth stays the twin's (docs/world.md).

Sizes (standard deviations of the draw: each term's expanded uncertainty U, k = 2, of the
instrument that measures it, docs/world.md's table; the wear uniform):

| term | size | basis |
|---|---|---|
| EZZ | 0.3 um + 1 ppm of travel | laser, U = 0.3 um + 1 ppm |
| EXZ, EYZ | 0.5 um | straightness optics, U = 0.5 um over 150 mm |
| EAZ, EBZ, ECZ | 0.3 arcsec | angular optics, U = 0.3 arcsec |
| EXC, EYC, EZC | 0.1 um | capacitive probe, U = 0.1 um |
| EAC, EBC | 1 arcsec | electronic level on the table, U = 1 arcsec |
| ECC | 1 arcsec | rotary calibrator, U = 1 arcsec |
| installation, alignment | 0.6 um, 1 arcsec | each error's own measurement; the tilts' levels |
| the axial datum | 0.6 um | calibrated on a master part, U = 0.6 um: the calibration block's z takes up the rest |
| EZZ lost motion | + 0 ... 1.5 um | nut wear |
| C runout | + 0 ... 1 um | bearing wear |
| EZZ scale | N(0, 1 ppm) | the screw warmer or cooler on the campaign's day |
| EZZ lead error | 0 ... 0.15 um, period 5 mm | a precision-grade ball screw's lead wobble |
"""

from __future__ import annotations

import math
import tomllib
from dataclasses import dataclass, fields, replace
from pathlib import Path

import numpy as np
import tomli_w

from station.effects import Backlash, Eccentricity, ErrorCurve, Periodic, Scale
from station.kinematics.model import StationModel, load_model
from station.kinematics.parameters import COMPONENTS, ErrorMotions, SixDof, motion_names

SIX_KEYS = ("x_um", "y_um", "z_um", "a_arcsec", "b_arcsec", "c_arcsec")


@dataclass(frozen=True)
class WorldSizes:
    """Standard deviations of a drawn world's departures from the model: each term's
    expanded uncertainty U (k = 2) of the campaign that measured it (module doc), so
    a drawn machine is off its model by what the certificate allows, the wear on top."""

    z_grid_mm: float = 5.0
    c_grid_deg: float = 10.0
    ezz_um: float = 0.3
    ezz_ppm: float = 1.0
    straightness_um: float = 0.5
    angular_z_arcsec: float = 0.3
    radial_c_um: float = 0.1
    tilt_c_arcsec: float = 1.0
    ecc_arcsec: float = 1.0
    installation_um: float = 0.6
    installation_arcsec: float = 1.0
    #: the axial datum (where the chain's static errors put the detection point along
    #: the bore at the master's holes) is calibrated on a master part, U = 0.6 um: the
    #: drawn static errors are shifted along the calibration block's z so the datum
    #: is off by this much (a draw), whatever the single errors add up to
    datum_um: float = 0.6
    #: the share of each curve's departure in its short-wave part (iid per grid point)
    short_wave: float = 0.3
    backlash_wear_um: float = 1.5
    runout_wear_um: float = 1.0
    scale_ppm: float = 1.0
    lead_error_um: float = 0.15
    lead_mm: float = 5.0

    def scaled(self, factor: float) -> "WorldSizes":
        """Every departure (not the grids, nor the short-wave share) times ``factor``: a
        machine further off its model (a knock, a year's wear) for studies."""
        keep = {"z_grid_mm", "c_grid_deg", "short_wave", "lead_mm"}
        return replace(self, **{f.name: getattr(self, f.name) * factor for f in fields(self) if f.name not in keep})

    def curve_sigma(self, motion: str) -> float:
        return {"EXZ": self.straightness_um, "EYZ": self.straightness_um, "EZZ": self.ezz_um,
                "EAZ": self.angular_z_arcsec, "EBZ": self.angular_z_arcsec, "ECZ": self.angular_z_arcsec,
                "EXC": self.radial_c_um, "EYC": self.radial_c_um, "EZC": self.radial_c_um,
                "EAC": self.tilt_c_arcsec, "EBC": self.tilt_c_arcsec, "ECC": self.ecc_arcsec}[motion]


def _smooth_linear(rng, x_mm: np.ndarray, sigma: float, short: float, length_mm: float = 40.0) -> np.ndarray:
    """A smooth departure over the stroke (squared-exponential correlation of length
    ``length_mm``) plus an independent short-wave part, total standard deviation ``sigma``."""
    d = x_mm[:, None] - x_mm[None, :]
    K = np.exp(-0.5 * (d / length_mm) ** 2) + 1e-9 * np.eye(x_mm.size)
    smooth = np.linalg.cholesky(K) @ rng.normal(0.0, 1.0, x_mm.size)
    return sigma * (math.sqrt(1.0 - short ** 2) * smooth + short * rng.normal(0.0, 1.0, x_mm.size))


def _smooth_rotary(rng, c_deg: np.ndarray, sigma: float, short: float, harmonics: int = 6) -> np.ndarray:
    """A periodic departure over the turn (harmonics 1..``harmonics``, amplitude falling
    as 1/k) plus an independent short-wave part, total standard deviation ``sigma``."""
    k = np.arange(1, harmonics + 1)
    amp = 1.0 / k
    amp = amp / math.sqrt((amp ** 2).sum())  # unit variance: a cos + b sin has variance 1 per harmonic
    a, b = rng.normal(0.0, 1.0, (2, harmonics))
    ph = np.radians(c_deg)[:, None] * k[None, :]
    smooth = (amp * (a * np.cos(ph) + b * np.sin(ph))).sum(axis=1)
    return sigma * (math.sqrt(1.0 - short ** 2) * smooth + short * rng.normal(0.0, 1.0, c_deg.size))


def _worn_effect(rng, e, sizes: WorldSizes, runout_wear_um: float):
    """A model's effect as the machine has it now: lost motion and runout grown by wear
    (the bearing's runout one eccentricity, of EXC and EYC alike), a periodic's
    amplitude and phase within its probe's uncertainty."""
    if isinstance(e, Backlash):
        return replace(e, reversal=e.reversal + float(rng.uniform(0.0, sizes.backlash_wear_um)))
    if isinstance(e, Eccentricity):
        return replace(e, amplitude=e.amplitude + runout_wear_um)
    if isinstance(e, Periodic):
        return replace(e, amplitude=e.amplitude + float(rng.normal(0.0, sizes.radial_c_um)),
                       phase=e.phase + float(rng.normal(0.0, 0.2)))
    return e


def draw_world_model(seed: int, base: StationModel | None = None, sizes: WorldSizes | None = None,
                     name: str | None = None) -> StationModel:
    """A machine that differs from ``base`` (default: the station's shipped model) by
    realistic amounts (module doc), drawn with ``seed``."""
    base = base or load_model()
    sizes = sizes or WorldSizes()
    rng = np.random.default_rng(seed)
    static = {}
    for body, is_motion, _ in base.parameter_blocks():
        if is_motion:
            continue
        v = base.static_of(body).values().copy()
        v[:3] += rng.normal(0.0, sizes.installation_um, 3)
        v[3:] += rng.normal(0.0, sizes.installation_arcsec, 3)
        static[body] = SixDof.from_values(v)
    z0, z1 = base.z_travel_mm
    z_grid = np.linspace(z0, z1, int(round((z1 - z0) / sizes.z_grid_mm)) + 1)
    c_grid = np.arange(0.0, 360.0, sizes.c_grid_deg)
    runout_wear_um = float(rng.uniform(0.0, sizes.runout_wear_um))
    motions = {}
    for body in base.joint_bodies:
        rotary = base.topology.by_name(body).joint == "revolute_z"
        grid = c_grid if rotary else z_grid
        curves = []
        for comp, mname in zip(COMPONENTS, motion_names(body)):
            cv = getattr(base.motions_of(body), comp)
            sigma = sizes.curve_sigma(mname)
            if rotary:
                dev = _smooth_rotary(rng, grid, sigma, sizes.short_wave)
            else:
                dev = _smooth_linear(rng, grid, sigma, sizes.short_wave)
                if mname == "EZZ":  # the laser's length-proportional part
                    dev = dev + rng.normal(0.0, sizes.ezz_ppm) * 1e-3 * (grid - z0)
            effects = [_worn_effect(rng, e, sizes, runout_wear_um) for e in cv.effects]
            if mname == "EZZ":
                effects.append(Scale(ppm=float(rng.normal(0.0, sizes.scale_ppm))))
                effects.append(Periodic(period=sizes.lead_mm, amplitude=float(rng.uniform(0.0, sizes.lead_error_um)),
                                        phase=float(rng.uniform(0.0, 2.0 * math.pi))))
            curves.append(ErrorCurve.table(grid, cv.baseline(grid) + dev, cv.kind, effects))
        motions[body] = ErrorMotions(*curves)
    world = replace(base, static_errors=static, motions=motions, name=name or f"drawn-world-{seed}")
    return _pin_datum(world, base, float(rng.normal(0.0, sizes.datum_um)))


#: where the axial datum is calibrated: the standard sample's holes (paper Table 4), C = 0
DATUM_Z_MM = (71.03, 85.19)


def _axial_datum_um(model: StationModel, reference: StationModel) -> float:
    """How far ``model`` puts the detection point along the bore beyond ``reference`` at
    the master's holes (um), less what the grating sees of it (EZZ: the carriage)."""
    z = np.asarray(DATUM_Z_MM)
    c = np.zeros_like(z)

    def axial(m):
        a, _, _ = m.part_coordinates(m.errors(z, c).actual_point_mm)
        return a * 1e3 - m.motions_of("Z").z.evaluate(z)

    return float(np.mean(axial(model) - axial(reference)))


def _pin_datum(world: StationModel, base: StationModel, datum_um: float, body: str = "J") -> StationModel:
    """``world`` with the calibration block's z error shifted so its axial datum is
    ``datum_um`` off the base model's (two Newton steps: the datum is linear in it to
    first order)."""
    for _ in range(2):
        off = _axial_datum_um(world, base) - datum_um
        v = world.static_of(body).values().copy()
        probe = v.copy()
        probe[2] += 1.0
        slope = _axial_datum_um(replace(world, static_errors={**world.static_errors, body: SixDof.from_values(probe)}),
                                base) - _axial_datum_um(world, base)
        v[2] -= off / slope
        world = replace(world, static_errors={**world.static_errors, body: SixDof.from_values(v)})
    return world


def model_to_dict(model: StationModel) -> dict:
    """A model as the data of a model file (``station.kinematics.model.model_from_dict``
    reads it back)."""
    out: dict = {"name": model.name,
                 "geometry": {"endoscope_offset_mm": list(model.endoscope_offset_mm),
                              "table_offset_mm": list(model.table_offset_mm),
                              "z_travel_mm": list(model.z_travel_mm)},
                 "installation": {}, "alignment": {}, "motions": {}}
    for body, sd in model.static_errors.items():
        section = "alignment" if body in model.joint_bodies else "installation"
        out[section][body] = {k: float(v) for k, v in zip(SIX_KEYS, sd.values())}
    for body, mo in model.motions.items():
        tables = {}
        for mname, cv in zip(motion_names(body), mo.curves()):
            if cv.is_zero:
                continue
            t: dict = {"target": [float(v) for v in cv.target], "deviation": [float(v) for v in cv.deviation]}
            if cv.effects:
                t["effects"] = [e.to_dict() for e in cv.effects]
            tables[mname] = t
        out["motions"][body] = tables
    return out


def write_world_scenario(folder: str | Path, seed: int, *, base: StationModel | None = None,
                         sizes: WorldSizes | None = None, template: str | Path | None = None,
                         world_model: StationModel | None = None, overrides: dict | None = None) -> Path:
    """Write ``world-<seed>.toml`` (the drawn machine) and ``scenario-<seed>.toml`` (the
    default scenario with its ``[world] model`` naming it and its repeatability seeded
    with ``seed``) into ``folder``; returns the scenario's path. ``world_model``: a
    caller's world instead of a drawn one; ``overrides``: tables laid over the
    scenario's ``[world]`` (e.g. ``{"screw_heating": {"enabled": False}}``)."""
    from sim.twins import DEFAULT_SCENARIO

    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    model = world_model if world_model is not None else draw_world_model(seed, base, sizes)
    model_path = folder / f"world-{seed}.toml"
    model_path.write_text(f"# a drawn world (sim/worlds.py, seed {seed}): the twin's machine, not the station's model\n"
                          + tomli_w.dumps(model_to_dict(model)))
    src = Path(template or DEFAULT_SCENARIO)
    data = tomllib.loads(src.read_text(encoding="utf-8-sig"))
    world = data.setdefault("world", {})
    world["model"] = model_path.name
    world.setdefault("repeatability", {})["seed"] = int(seed)
    for key, table in (overrides or {}).items():
        if isinstance(table, dict) and isinstance(world.get(key), dict):
            world[key] = {**world[key], **table}
        else:
            world[key] = table
    path = folder / f"scenario-{seed}.toml"
    path.write_text(f"# {src.name} with a drawn world (sim/worlds.py, seed {seed})\n" + tomli_w.dumps(data))
    return path
