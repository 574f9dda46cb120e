"""The effect vocabulary: one definition of every error effect the station knows.

The same formulas make the simulated world err (``sim``), undo the error
(compensation) and are fitted to a mismatch between the twin and a recording
(discovery).  The public names and parameters are those of the contract
``shared/spec/discovery.md`` section 2; keep them exactly.

Conventions (from the contract):

* position ``x`` in mm (linear) or degrees (rotary);
* deviation ``d`` in um (linear) or arcsec (rotary) -- *actual minus commanded*;
* ``k`` converts a position unit into a deviation unit: 1000 um/mm, 3600 arcsec/deg;
* ``s`` is the approach direction (+1 towards larger targets, -1 the other way,
  0 where unknown: direction-dependent effects then contribute their mean, 0);
* ``t`` is ``time_s``; ``T`` is ``temperature_c`` (when unknown, ``t_ref``: no
  thermal expansion is assumed, and the caller should say so).

Beyond the contract's table the station knows ``local_defect`` (a bump or dip in
one stretch of the travel), ``step`` (a grating-segment joint: the error jumps
at one position and stays) and ``abbe`` (offset times the recorded angle); they
are documented in ``docs/discovery.md`` with their physics.

Every effect is a small frozen dataclass with ``evaluate(ctx)`` vectorised over
numpy arrays, ``parameter_names`` and ``explanation`` (plain language, for
reports). Effects are *linear in at least some parameters*; ``jacobian`` gives
d(deviation)/d(parameter) numerically-exactly for the fit in discovery.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from typing import Any, ClassVar, Mapping

import numpy as np

#: deviation units per position unit (contract: ``k``)
K_LINEAR_UM_PER_MM = 1000.0
K_ROTARY_ARCSEC_PER_DEG = 3600.0


def k_for_kind(kind: str) -> float:
    """The contract's ``k`` for an axis kind (``linear`` or ``rotary``)."""
    if kind == "linear":
        return K_LINEAR_UM_PER_MM
    if kind == "rotary":
        return K_ROTARY_ARCSEC_PER_DEG
    raise ValueError(f"axis kind must be 'linear' or 'rotary', not {kind!r}")


@dataclass(frozen=True)
class EvalContext:
    """Where and when an effect is evaluated: N points, all arrays of shape (N,).

    ``direction``, ``time_s`` and ``temperature_c`` may be ``None`` when not known.
    """

    x: np.ndarray
    kind: str = "linear"
    direction: np.ndarray | None = None
    time_s: np.ndarray | None = None
    temperature_c: np.ndarray | None = None
    #: further measured channels by column name (e.g. ``angle_arcsec``: the pitch or
    #: yaw the laser's angular optics recorded at each point), for effects that need them
    channels: Mapping[str, np.ndarray] | None = None

    @property
    def k(self) -> float:
        return k_for_kind(self.kind)

    def channel(self, name: str) -> np.ndarray | None:
        return None if self.channels is None else self.channels.get(name)

    @classmethod
    def make(cls, x, kind="linear", direction=None, time_s=None, temperature_c=None, channels=None) -> "EvalContext":
        def arr(v):
            if v is None:
                return None
            return np.broadcast_to(np.asarray(v, dtype=float), np.shape(x)).astype(float)

        ch = None if not channels else {k: arr(v) for k, v in channels.items()}
        return cls(np.asarray(x, dtype=float), kind, arr(direction), arr(time_s), arr(temperature_c), ch)


class Effect:
    """Base of all effects. Subclasses are frozen dataclasses of float parameters."""

    name: ClassVar[str]
    explanation: ClassVar[str]
    #: which axis kinds the effect makes sense for
    kinds: ClassVar[tuple[str, ...]] = ("linear", "rotary")
    #: what the effect needs from the recording besides position
    needs: ClassVar[tuple[str, ...]] = ()

    def evaluate(self, ctx: EvalContext) -> np.ndarray:  # pragma: no cover - abstract
        raise NotImplementedError

    @property
    def parameter_names(self) -> tuple[str, ...]:
        return tuple(f.name for f in dataclasses.fields(self))  # type: ignore[arg-type]

    @property
    def parameters(self) -> dict[str, float]:
        return {n: float(getattr(self, n)) for n in self.parameter_names}

    def with_parameters(self, **values: float) -> "Effect":
        return dataclasses.replace(self, **values)  # type: ignore[type-var]

    def jacobian(self, ctx: EvalContext, names: tuple[str, ...] | None = None) -> np.ndarray:
        """d(deviation)/d(parameter) at ``ctx``, shape (N, len(names)), by central differences.

        The step is relative to the parameter (or 1e-6 absolute at zero); every
        vocabulary effect is smooth in its parameters, so this is accurate to ~1e-9.
        """
        names = names or self.parameter_names
        cols = []
        for n in names:
            v = float(getattr(self, n))
            h = 1e-6 * max(1.0, abs(v))
            up = self.with_parameters(**{n: v + h}).evaluate(ctx)
            dn = self.with_parameters(**{n: v - h}).evaluate(ctx)
            cols.append((up - dn) / (2 * h))
        return np.stack(cols, axis=1) if cols else np.zeros((len(ctx.x), 0))

    def to_dict(self) -> dict[str, Any]:
        return {"name": self.name, **self.parameters}


def _direction(ctx: EvalContext) -> np.ndarray:
    return np.zeros_like(ctx.x) if ctx.direction is None else ctx.direction


@dataclass(frozen=True)
class Offset(Effect):
    value: float = 0.0
    name: ClassVar[str] = "offset"
    explanation: ClassVar[str] = (
        "a constant shift of every reading: a zero (reference mark, home switch or "
        "instrument datum) that is not where the model puts it"
    )

    def evaluate(self, ctx):
        return np.full_like(ctx.x, self.value)


@dataclass(frozen=True)
class Scale(Effect):
    ppm: float = 0.0
    name: ClassVar[str] = "scale"
    explanation: ClassVar[str] = (
        "an error growing in proportion to position: the scale (grating pitch, screw lead, "
        "gear ratio) is longer or shorter than nominal, or the laser's wavelength "
        "compensation (air temperature, pressure, humidity) is off"
    )

    def evaluate(self, ctx):
        return self.ppm * 1e-6 * ctx.k * ctx.x


@dataclass(frozen=True)
class Backlash(Effect):
    reversal: float = 0.0
    name: ClassVar[str] = "backlash"
    explanation: ClassVar[str] = (
        "lost motion when the axis reverses: play in the screw nut, coupling or gears, or "
        "friction-induced elastic wind-up, makes the position reached depend on the "
        "direction of approach (ISO 230-2 reversal value B)"
    )
    needs: ClassVar[tuple[str, ...]] = ("direction",)

    def evaluate(self, ctx):
        return _direction(ctx) * self.reversal / 2.0


@dataclass(frozen=True)
class Periodic(Effect):
    period: float = 1.0
    amplitude: float = 0.0
    phase: float = 0.0
    name: ClassVar[str] = "periodic"
    explanation: ClassVar[str] = (
        "an error that repeats with position: screw-lead wobble (period = lead), "
        "gear-tooth or worm error, or a cyclic interpolation error of the scale"
    )

    def evaluate(self, ctx):
        return self.amplitude * np.sin(2.0 * np.pi * ctx.x / self.period + self.phase)


@dataclass(frozen=True)
class ThermalExpansion(Effect):
    coefficient: float = 0.0
    t_ref: float = 20.0
    name: ClassVar[str] = "thermal_expansion"
    explanation: ClassVar[str] = (
        "the scale or the structure grows with temperature: an error proportional to "
        "position and to the difference from the reference temperature (20 degC, ISO 1)"
    )
    needs: ClassVar[tuple[str, ...]] = ("temperature_c",)

    def evaluate(self, ctx):
        if ctx.temperature_c is None:
            return np.zeros_like(ctx.x)
        return self.coefficient * 1e-6 * ctx.k * ctx.x * (ctx.temperature_c - self.t_ref)


@dataclass(frozen=True)
class ThermalDrift(Effect):
    amplitude: float = 0.0
    tau: float = 600.0
    name: ClassVar[str] = "thermal_drift"
    explanation: ClassVar[str] = (
        "a position-independent shift that settles exponentially with time: the machine "
        "warming up (motor, bearings, nut) and the structure between scale and tool "
        "growing until it reaches equilibrium"
    )
    needs: ClassVar[tuple[str, ...]] = ("time_s",)

    def evaluate(self, ctx):
        if ctx.time_s is None:
            return np.zeros_like(ctx.x)
        tau = max(abs(self.tau), 1e-9)
        return self.amplitude * (1.0 - np.exp(-ctx.time_s / tau))


@dataclass(frozen=True)
class Eccentricity(Effect):
    amplitude: float = 0.0
    phase: float = 0.0
    name: ClassVar[str] = "eccentricity"
    kinds: ClassVar[tuple[str, ...]] = ("rotary",)
    explanation: ClassVar[str] = (
        "a once-per-revolution error: the angle encoder's graduation is not centred on "
        "the axis of rotation (or the axis runs out), so the angle read is off by a "
        "sine of the angle"
    )

    def evaluate(self, ctx):
        return self.amplitude * np.sin(np.radians(ctx.x) + self.phase)


@dataclass(frozen=True)
class LocalDefect(Effect):
    """A Gaussian bump: ``amplitude * exp(-((x - centre) / width)^2 / 2)``.

    Not in the contract's vocabulary; defined here beside it so that a model file
    naming ``local_defect`` is understood by the twin and by discovery alike.
    """

    centre: float = 0.0
    width: float = 1.0
    amplitude: float = 0.0
    name: ClassVar[str] = "local_defect"
    explanation: ClassVar[str] = (
        "a bump or dip confined to one part of the travel: a damaged, dirty or "
        "re-glued spot of the scale, a worn or dented stretch of the screw or "
        "guideway, a joint between scale segments; modelled as a Gaussian bump "
        "(amplitude at the centre, width = its standard deviation, in position units)"
    )

    def evaluate(self, ctx):
        w = np.maximum(np.abs(self.width), 1e-12)
        return self.amplitude * np.exp(-0.5 * ((ctx.x - self.centre) / w) ** 2)


@dataclass(frozen=True)
class Step(Effect):
    """A jump of ``height`` at ``position`` that stays: ``height * (x >= position)``.

    Not in the contract's vocabulary; defined here beside it so that a model file
    naming ``step`` is understood by the twin and by discovery alike.  A linear
    axis only: a rotary encoder ring closes on itself, so one jump round a turn
    would have to be undone somewhere else.
    """

    position: float = 0.0
    height: float = 0.0
    name: ClassVar[str] = "step"
    kinds: ClassVar[tuple[str, ...]] = ("linear",)
    explanation: ClassVar[str] = (
        "a jump in the error at one position that stays beyond it: the joint between two "
        "segments of the scale (a spliced grating tape, two glass scales butted end to end, "
        "a segmented screw or rack), where the second segment's graduation does not continue "
        "the first's; height = how far the second segment is off, position = the joint"
    )

    def evaluate(self, ctx):
        return np.where(ctx.x >= self.position, self.height, 0.0)


#: the recording column an Abbe error reads: the angular error (pitch or yaw) that
#: the laser's angular optics recorded at each point, arcsec
ABBE_CHANNEL = "angle_arcsec"


@dataclass(frozen=True)
class AbbeError(Effect):
    """``arm_mm * angle``: the angular error at each point times the Abbe offset."""

    arm_mm: float = 0.0
    name: ClassVar[str] = "abbe"
    kinds: ClassVar[tuple[str, ...]] = ("linear",)
    needs: ClassVar[tuple[str, ...]] = (ABBE_CHANNEL,)
    explanation: ClassVar[str] = (
        "the Abbe error: the point measured is offset from the line the scale (or the laser "
        "beam) measures along, so every pitch or yaw of the carriage tilts the offset and "
        "shifts the point by offset x angle; found from the angle recorded at each point"
    )

    def evaluate(self, ctx):
        angle = ctx.channel(ABBE_CHANNEL)
        if angle is None:
            return np.zeros_like(ctx.x)
        # arcsec -> rad (pi / 648000), mm -> deviation unit (k: um per mm)
        return self.arm_mm * angle * (np.pi / 648000.0) * ctx.k


#: the contract's vocabulary by name, plus the effects the station adds to it
VOCABULARY: dict[str, type[Effect]] = {
    cls.name: cls
    for cls in (Offset, Scale, Backlash, Periodic, ThermalExpansion, ThermalDrift, Eccentricity, LocalDefect, Step,
                AbbeError)
}


def register(cls: type[Effect]) -> type[Effect]:
    """Add an effect class to the vocabulary (decorator); names must be unique."""
    if cls.name in VOCABULARY and VOCABULARY[cls.name] is not cls:
        raise ValueError(f"effect name {cls.name!r} is already registered")
    VOCABULARY[cls.name] = cls
    return cls


class EffectSpecError(ValueError):
    """A model file names an unknown effect or a bad parameter."""


def effect_from_dict(d: Mapping[str, Any], where: str = "") -> Effect:
    """Build an effect from ``{"name": ..., param: value, ...}``; unknown names and
    parameters are refused with ``where`` (file and entry) in the message."""
    prefix = f"{where}: " if where else ""
    if "name" not in d:
        raise EffectSpecError(f"{prefix}effect without a 'name'")
    name = d["name"]
    cls = VOCABULARY.get(name)
    if cls is None:
        raise EffectSpecError(f"{prefix}unknown effect {name!r}; known: {', '.join(sorted(VOCABULARY))}")
    allowed = {f.name for f in dataclasses.fields(cls)}
    kwargs: dict[str, float] = {}
    for key, value in d.items():
        if key == "name":
            continue
        if key not in allowed:
            raise EffectSpecError(f"{prefix}effect {name!r} has no parameter {key!r}; it takes {sorted(allowed)}")
        try:
            fv = float(value)
        except (TypeError, ValueError):
            raise EffectSpecError(f"{prefix}effect {name!r} parameter {key!r} is not a number: {value!r}") from None
        if not math.isfinite(fv):
            raise EffectSpecError(f"{prefix}effect {name!r} parameter {key!r} is not finite: {value!r}")
        kwargs[key] = fv
    return cls(**kwargs)


#: a rotary table whose span is within this of 360 deg covers a whole turn
ROTARY_TURN_TOL_DEG = 1e-6
#: how far the two ends of a whole-turn rotary table may differ (arcsec): the
#: resolution of a rotary calibrator's reading (0.01 arcsec), not a physical effect
ROTARY_CLOSE_TOL = 0.01


@dataclass(frozen=True)
class ErrorCurve:
    """One error motion as a function of position: a baseline table, linearly
    interpolated and held flat outside (modulo 360 deg for a rotary axis), plus
    any effects of the vocabulary.  Deviation units (um or arcsec).

    This is the axis model of the contract *and* one of the 13 error motions of
    the kinematic model: one definition for the twin, compensation and discovery.
    """

    kind: str = "linear"
    target: tuple[float, ...] = ()
    deviation: tuple[float, ...] = ()
    effects: tuple[Effect, ...] = field(default_factory=tuple)

    def __post_init__(self):
        k_for_kind(self.kind)
        if len(self.target) != len(self.deviation):
            raise ValueError("baseline target and deviation differ in length")
        t = np.asarray(self.target, dtype=float)
        if t.size and np.any(np.diff(t) <= 0):
            raise ValueError("baseline targets must be strictly increasing")
        if self.kind == "rotary" and t.size > 1 and t[-1] - t[0] >= 360.0 - ROTARY_TURN_TOL_DEG:
            # A rotary error curve is periodic: 0 and 360 deg are one table position.
            # A table over a whole turn must close, or it would step silently at the
            # wrap (issue 18); it is refused, naming both ends (docs/error-model.md).
            d0, d1 = self.deviation[0], self.deviation[-1]
            if t[-1] - t[0] > 360.0 + ROTARY_TURN_TOL_DEG:
                raise ValueError(f"rotary baseline spans {t[0]:g}..{t[-1]:g} deg, more than one turn")
            if abs(d1 - d0) > ROTARY_CLOSE_TOL:
                raise ValueError(f"rotary baseline spans a whole turn but does not close: {d0:g} arcsec at "
                                 f"{t[0]:g} deg, {d1:g} arcsec at {t[-1]:g} deg (the same table position); "
                                 "give the turn without its last point, or make both ends equal")

    @classmethod
    def zero(cls, kind: str = "linear") -> "ErrorCurve":
        return cls(kind=kind)

    @classmethod
    def table(cls, target, deviation, kind: str = "linear", effects=()) -> "ErrorCurve":
        return cls(kind, tuple(map(float, target)), tuple(map(float, deviation)), tuple(effects))

    @property
    def is_zero(self) -> bool:
        return not self.effects and not any(self.deviation)

    def baseline(self, x: np.ndarray) -> np.ndarray:
        x = np.asarray(x, dtype=float)
        if not self.target:
            return np.zeros_like(x)
        t = np.asarray(self.target)
        d = np.asarray(self.deviation)
        if self.kind == "rotary":
            if len(t) > 1 and t[-1] - t[0] >= 360.0 - ROTARY_TURN_TOL_DEG:
                t, d = t[:-1], d[:-1]  # a closed turn: its last point is its first
            # periodic: a table over less than a turn is closed linearly across its gap
            return np.interp(np.mod(x, 360.0), t, d, period=360.0) if len(t) > 1 else np.full_like(x, d[0])
        return np.interp(x, t, d)

    def evaluate(self, x, direction=None, time_s=None, temperature_c=None, channels=None) -> np.ndarray:
        ctx = EvalContext.make(x, self.kind, direction, time_s, temperature_c, channels)
        return self.evaluate_ctx(ctx)

    def evaluate_ctx(self, ctx: EvalContext) -> np.ndarray:
        out = self.baseline(ctx.x)
        for e in self.effects:
            out = out + e.evaluate(ctx)
        return out

    def with_effects(self, *effects: Effect) -> "ErrorCurve":
        return dataclasses.replace(self, effects=tuple(self.effects) + tuple(effects))
