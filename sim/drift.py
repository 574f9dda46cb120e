"""What the machine does that no model of it says: heat, air, wear, a knock.

The world (``sim.world``) applies its error model, which speaks the effect vocabulary
of ``station.effects`` like the station's own. A real machine moves on from any model
measured of it; these are the physics by which the twin's machine does, each a small
object with its parameters, its state, and the displacement it causes
(docs/world.md gives each one's physical basis and its default):

* :class:`ScrewHeating` -- the Z drive's own duty cycle heats its ball screw (friction
  in the nut and the support bearings, a first-order lag); the screw grows from its
  fixed bearing and the carriage with it. The grating sees it; the model does not.
* :class:`Ambient` -- the shop's air steps to a new temperature; the part, the frame and
  the grating follow it each with its own time constant and expand with its own
  coefficient. The part's holes move away from its datum face; the structural loop
  between the table and the detection point that the grating does not measure moves
  the point; the grating's own scale reads short or long.
* :class:`Wear` -- Z's lost motion grows with its travel, C's radial runout with its turns.
* :class:`Collision` -- at an instant, a body's installation errors step (a datum
  knocked, the endoscope's mount bent).

Times are the drives' clock (s since power-on, scaled by the scenario's time scale);
temperatures degC; the reference temperature of drawings and of the station's model is
20 degC (ISO 1).
"""

from __future__ import annotations

import math
import threading
from dataclasses import dataclass, field, fields
from typing import Any, Mapping

#: the reference temperature of dimensional metrology (ISO 1)
REFERENCE_C = 20.0


def _lag(start_c: float, step_c: float, at_s: float, tau_s: float, t_s: float) -> float:
    """A first-order body's temperature after its surroundings stepped by ``step_c`` at ``at_s``."""
    if step_c == 0.0 or t_s <= at_s:
        return start_c
    return start_c + step_c * (1.0 - math.exp(-(t_s - at_s) / tau_s))


@dataclass
class ScrewHeating:
    """The ball screw of Z warms with the axis' own motion.

    First-order lag of the screw's mean temperature rise ``dT`` over the shop's:
    ``tau * d(dT)/dt = rise_k_per_mm_s * |v(t)| - dT``, so moving steadily at a mean
    speed ``v`` the screw settles ``rise_k_per_mm_s * v`` above the air. Each move
    deposits its distance at once (moves last seconds, ``tau`` many minutes). The
    screw grows from its fixed bearing at ``fixed_end_mm``:
    ``growth = alpha * dT * (z - fixed_end)``."""

    enabled: bool = False
    #: steel of the screw, ppm/K
    alpha_ppm_per_k: float = 11.7
    #: steady rise per mm/s of mean speed, K (a preloaded 16 mm screw: about 3 K at 20 mm/s)
    rise_k_per_mm_s: float = 0.15
    #: the screw's thermal time constant, s
    tau_s: float = 1200.0
    #: where the fixed (axial) bearing holds the screw, mm of Z
    fixed_end_mm: float = 0.0

    def __post_init__(self):
        self._lock = threading.Lock()
        self._rise_k = 0.0
        self._at_s = 0.0

    def on_move(self, distance_mm: float, t_s: float) -> None:
        if not self.enabled:
            return
        with self._lock:
            self._rise_k = self._decayed(t_s) + self.rise_k_per_mm_s * abs(distance_mm) / self.tau_s
            self._at_s = max(self._at_s, t_s)

    def _decayed(self, t_s: float) -> float:
        return self._rise_k * math.exp(-max(0.0, t_s - self._at_s) / self.tau_s)

    def rise_k(self, t_s: float) -> float:
        with self._lock:
            return self._decayed(t_s)

    def growth_um(self, z_mm: float, t_s: float) -> float:
        """How far the carriage at motor position ``z_mm`` is carried by the warm screw (um)."""
        if not self.enabled:
            return 0.0
        return self.alpha_ppm_per_k * 1e-6 * self.rise_k(t_s) * (z_mm - self.fixed_end_mm) * 1e3


@dataclass
class Ambient:
    """The shop's air: ``start_c``, stepping by ``step_c`` at ``at_s``. Each body lags
    it with its own time constant and expands with its own coefficient, about its own
    fixed point:

    * the part (a cast aluminium body) from its datum face on the table: a hole at
      ``a`` (at 20 degC) is at ``a * (1 + alpha_part * (T_part - 20))``;
    * the structural loop between the table's face and the detection point that the
      grating does not measure, ``frame_loop_mm`` of steel (signed: positive carries
      the point up as it grows). By default -150 mm: 50 mm of column below the
      grating's fixed end, less the 200 mm endoscope hanging below the slide;
    * the grating (a glass-ceramic scale) from its fixed end: it reads
      ``(1 - alpha_grating * (T_grating - 20))`` of the distance from there.
    """

    start_c: float = REFERENCE_C
    step_c: float = 0.0
    at_s: float = 0.0
    part_alpha_ppm_per_k: float = 23.0
    part_tau_s: float = 600.0
    frame_alpha_ppm_per_k: float = 11.5
    frame_tau_s: float = 5400.0
    frame_loop_mm: float = -150.0
    grating_alpha_ppm_per_k: float = 8.0
    grating_tau_s: float = 1800.0
    grating_fixed_mm: float = 0.0

    def part_c(self, t_s: float) -> float:
        return _lag(self.start_c, self.step_c, self.at_s, self.part_tau_s, t_s)

    def frame_c(self, t_s: float) -> float:
        return _lag(self.start_c, self.step_c, self.at_s, self.frame_tau_s, t_s)

    def grating_c(self, t_s: float) -> float:
        return _lag(self.start_c, self.step_c, self.at_s, self.grating_tau_s, t_s)

    def part_scale(self, t_s: float) -> float:
        """How much longer the part is than at 20 degC (about its datum face)."""
        return 1.0 + self.part_alpha_ppm_per_k * 1e-6 * (self.part_c(t_s) - REFERENCE_C)

    def part_axial_mm(self, axial_20_mm: float, t_s: float) -> float:
        return axial_20_mm * self.part_scale(t_s)

    def frame_shift_um(self, t_s: float) -> float:
        """How far the frame's growth carries the detection point along the bore (um, +up)."""
        return self.frame_alpha_ppm_per_k * 1e-6 * (self.frame_c(t_s) - REFERENCE_C) * self.frame_loop_mm * 1e3

    def grating_error_um(self, carriage_mm: float, t_s: float) -> float:
        """Reading minus the true carriage position (um): a warm scale reads short."""
        d = carriage_mm - self.grating_fixed_mm
        return -self.grating_alpha_ppm_per_k * 1e-6 * (self.grating_c(t_s) - REFERENCE_C) * d * 1e3


@dataclass
class Wear:
    """Z's lost motion grows with its travel (the nut's balls and races wear, the
    preload relaxes); C's radial runout with its turns (bearing wear). Linear in use:
    over a campaign, not a machine's life."""

    backlash_um_per_m: float = 0.0
    runout_um_per_kturn: float = 0.0

    def __post_init__(self):
        self._lock = threading.Lock()
        self._z_travel_mm = 0.0
        self._c_travel_deg = 0.0

    def on_move(self, axis: str, distance: float) -> None:
        """A move of ``distance`` (mm for Z, deg for C) started."""
        with self._lock:
            if axis == "Z":
                self._z_travel_mm += abs(distance)
            else:
                self._c_travel_deg += abs(distance)

    def backlash_extra_um(self) -> float:
        with self._lock:
            return self.backlash_um_per_m * self._z_travel_mm * 1e-3

    def runout_extra_um(self) -> float:
        with self._lock:
            return self.runout_um_per_kturn * self._c_travel_deg / 360.0 * 1e-3


SIX_DOF_KEYS = ("x_um", "y_um", "z_um", "a_arcsec", "b_arcsec", "c_arcsec")


@dataclass
class Collision:
    """At ``at_s`` a body's installation errors step by ``shift`` (x_um ... c_arcsec):
    a collision knocked the calibration block, bent the endoscope's mount. ``at_s``
    None: never."""

    at_s: float | None = None
    body: str = "J"
    shift: dict[str, float] = field(default_factory=dict)

    def __post_init__(self):
        unknown = set(self.shift) - set(SIX_DOF_KEYS)
        if unknown:
            raise ValueError(f"collision shift: unknown keys {sorted(unknown)}; use {SIX_DOF_KEYS}")

    def happened(self, t_s: float) -> bool:
        return self.at_s is not None and t_s >= self.at_s


@dataclass
class Drift:
    """All of the above for one world (each off or at rest by default)."""

    screw: ScrewHeating = field(default_factory=ScrewHeating)
    ambient: Ambient = field(default_factory=Ambient)
    wear: Wear = field(default_factory=Wear)
    collision: Collision = field(default_factory=Collision)


def _build(cls, data: Mapping[str, Any], section: str, source: str):
    names = {f.name for f in fields(cls)}
    unknown = set(data) - names
    if unknown:
        raise ValueError(f"{source}: [{section}] unknown keys {sorted(unknown)}; known: {sorted(names)}")
    kw = {}
    for f in fields(cls):
        if f.name not in data:
            continue
        v = data[f.name]
        try:
            if f.name == "enabled":
                if not isinstance(v, bool):
                    raise TypeError
                kw[f.name] = v
            elif f.name == "body":
                kw[f.name] = str(v)
            elif f.name == "shift":
                kw[f.name] = {str(k): float(x) for k, x in dict(v).items()}
            elif f.name == "at_s" and v is None:
                kw[f.name] = None
            else:
                x = float(v)
                if not math.isfinite(x):
                    raise ValueError
                kw[f.name] = x
        except (TypeError, ValueError):
            raise ValueError(f"{source}: [{section}] {f.name} = {v!r} is not valid") from None
    for name in ("tau_s", "part_tau_s", "frame_tau_s", "grating_tau_s"):
        if name in kw and kw[name] <= 0:
            raise ValueError(f"{source}: [{section}] {name} must be positive")
    try:
        return cls(**kw)
    except ValueError as exc:
        raise ValueError(f"{source}: [{section}] {exc}") from None


def drift_from_dict(world: Mapping[str, Any], source: str = "<dict>") -> Drift:
    """The drift physics of a scenario's ``[world]`` table: ``[world.screw_heating]``,
    ``[world.ambient]``, ``[world.wear]``, ``[world.collision]`` (all optional)."""
    return Drift(
        screw=_build(ScrewHeating, world.get("screw_heating", {}), "world.screw_heating", source),
        ambient=_build(Ambient, world.get("ambient", {}), "world.ambient", source),
        wear=_build(Wear, world.get("wear", {}), "world.wear", source),
        collision=_build(Collision, world.get("collision", {}), "world.collision", source),
    )
