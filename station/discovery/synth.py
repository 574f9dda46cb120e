"""Realistic synthetic recordings with concealed effects, for tests and the bench.

A recording is made the way a laser-interferometer campaign is: ISO 230-2 cycles
(each run approaches every target in the + direction, then every target in the -
direction, with an overrun before each reversal), targets spaced irregularly
(ISO 230-2:2014 5.3.2 asks for irregular spacing so periodic errors are not
aliased), time advancing with the move and a dwell at every target, optional dense
short-step runs for periodic errors, and AR(1) noise along each run.  The truth is
the model's own prediction plus hidden effects from the vocabulary -- the same
classes the discovery fits, so nothing is written twice.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from station.axis_model import AxisModel, axis_model_from_dict
from station.effects import Effect, EvalContext
from station.recording import Recording

#: a Z axis of the station: 0..120 mm travel (architecture: endoscope on Z)
Z_TRAVEL_MM = (0.0, 120.0)
#: rotary table C calibrated over 0..345 deg in 15 deg nominal steps
C_RANGE_DEG = (0.0, 345.0)


@dataclass
class Campaign:
    """How the recording is taken.  Times in s, speeds in position units per s."""

    kind: str = "linear"
    n_targets: int = 11
    span: tuple[float, float] = Z_TRAVEL_MM
    jitter_fraction: float = 0.25        # of the nominal spacing, uniform
    n_runs: int = 5
    speed: float = 5.0                   # mm/s (or deg/s)
    dwell_s: float = 4.0                 # settle + averaging at every target
    pause_s: float = 30.0                # between runs
    dense_runs: int = 0                  # extra short-step runs (each +, then -)
    dense_span: tuple[float, float] | None = None
    dense_step: float = 0.5
    sigma: float = 0.5                   # marginal noise sd, deviation units
    phi: float = 0.3                     # AR(1) coefficient along each run
    temperature: tuple[float, float] | None = None   # start, end degC (linear ramp) or None
    temperature_tau_s: float | None = None           # exponential approach instead of a ramp
    time_zero: bool = False              # untrustworthy time column (all zero)
    seed: int = 0


def irregular_targets(c: Campaign, rng: np.random.Generator) -> np.ndarray:
    lo, hi = c.span
    nominal = np.linspace(lo, hi, c.n_targets)
    step = (hi - lo) / max(c.n_targets - 1, 1)
    jitter = rng.uniform(-c.jitter_fraction, c.jitter_fraction, c.n_targets) * step
    jitter[0] = jitter[-1] = 0.0  # the travel ends are measured where they are
    return np.round(nominal + jitter, 3)


def schedule(c: Campaign, rng: np.random.Generator):
    """Rows (time, run, direction, target) of the whole campaign, in time order."""
    targets = irregular_targets(c, rng)
    rows: list[tuple[float, int, int, float]] = []
    t = 0.0
    pos = targets[0]

    def visit(run, direction, seq):
        nonlocal t, pos
        for x in seq:
            t += abs(x - pos) / c.speed + c.dwell_s
            pos = x
            rows.append((t, run, direction, float(x)))
        t += c.dwell_s  # overrun and reversal (ISO 230-2: approach from beyond)

    for r in range(1, c.n_runs + 1):
        visit(r, +1, targets)
        visit(r, -1, targets[::-1])
        t += c.pause_s
    if c.dense_runs:
        lo, hi = c.dense_span or c.span
        dense = np.round(np.arange(lo, hi + 1e-9, c.dense_step), 4)
        for k in range(c.dense_runs):
            r = c.n_runs + 1 + k
            visit(r, +1, dense)
            visit(r, -1, dense[::-1])
            t += c.pause_s
    a = np.array(rows)
    return a[:, 0], a[:, 1].astype(int), a[:, 2].astype(int), a[:, 3]


def ar1_noise(run: np.ndarray, sigma: float, phi: float, rng: np.random.Generator) -> np.ndarray:
    """AR(1) noise with marginal sd ``sigma``, restarting (stationary) at every run."""
    e = rng.normal(0.0, sigma * np.sqrt(1 - phi ** 2), run.size)
    out = np.empty(run.size)
    for i in range(run.size):
        if i == 0 or run[i] != run[i - 1]:
            out[i] = rng.normal(0.0, sigma)
        else:
            out[i] = phi * out[i - 1] + e[i]
    return out


def make_recording(model: AxisModel, hidden: tuple[Effect, ...], c: Campaign,
                   outliers: dict[int, float] | None = None) -> Recording:
    """The recording a campaign ``c`` would give on an axis whose truth is ``model``
    plus ``hidden`` effects; ``outliers`` adds a gross error at given row indices."""
    rng = np.random.default_rng(c.seed)
    time_s, run, direction, target = schedule(c, rng)
    temp = None
    if c.temperature is not None:
        t0, t1 = c.temperature
        if c.temperature_tau_s:
            temp = t0 + (t1 - t0) * (1 - np.exp(-time_s / c.temperature_tau_s))
        else:
            temp = t0 + (t1 - t0) * time_s / max(time_s[-1], 1e-9)
        temp = np.round(temp + rng.normal(0, 0.01, temp.size), 3)  # sensor noise 0.01 K
    rec = Recording(time_s=time_s, run=run, direction=direction, target=target,
                    deviation=np.zeros_like(target), temperature_c=temp,
                    metadata={"axis": model.name, "kind": model.kind, "instrument": "synthetic"})
    ctx = EvalContext.make(target, model.kind, direction, time_s, temp)
    truth = model.predict(rec) + sum((e.evaluate(ctx) for e in hidden), np.zeros_like(target))
    dev = truth + ar1_noise(run, c.sigma, c.phi, rng)
    for i, v in (outliers or {}).items():
        dev[i] += v
    rec.deviation = np.round(dev, 4)
    if c.time_zero:
        rec.time_s = np.zeros_like(time_s)
    rec.line = np.arange(len(rec)) + 2 + len(rec.metadata)
    return rec


def linear_model(sigma: float = 0.5) -> AxisModel:
    """A Z axis model with a realistic baseline (pitch error growing along the travel)."""
    return axis_model_from_dict({
        "axis": {"name": "Z", "kind": "linear"},
        "baseline": {"target": [0.0, 20.0, 40.0, 60.0, 80.0, 100.0, 120.0],
                     "deviation": [0.0, 3.1, 6.0, 9.2, 12.1, 15.3, 18.0]},
        "noise": {"sigma": sigma},
    }, "synthetic-linear")


def rotary_model(sigma: float = 0.4) -> AxisModel:
    """A C table model whose baseline carries a monotone (cumulative pitch) error."""
    tgt = np.arange(0.0, 346.0, 15.0)
    dev = np.round(-0.03 * tgt + 2.0 * np.sqrt(tgt / 345.0), 3)  # arcsec, monotone decreasing
    return axis_model_from_dict({
        "axis": {"name": "C", "kind": "rotary"},
        "baseline": {"target": tgt.tolist(), "deviation": dev.tolist()},
        "noise": {"sigma": sigma},
    }, "synthetic-rotary")


def rotary_campaign(**kw) -> Campaign:
    base = dict(kind="rotary", n_targets=24, span=C_RANGE_DEG, speed=10.0, sigma=0.4)
    base.update(kw)
    return Campaign(**base)


# ----------------------------------------------------------------- structure outside the vocabulary

#: kinds of structure the vocabulary has no sine, line or constant for (issue 20), and
#: their variants; ``step`` has a vocabulary effect since, the others none
OOV_VARIANTS: dict[str, tuple[str, ...]] = {
    "step": ("step",),
    "curvature": ("quadratic", "quadratic_from_zero", "cubic", "cubic_from_zero", "quadratic_cubic"),
    "nonsine_periodic": ("sawtooth", "triangle", "square"),
    "growing_hysteresis": ("with_position", "with_distance"),
}


def distance_travelled(rec: Recording) -> np.ndarray:
    """Distance the axis has moved since the campaign's first reading (file = time order)."""
    return np.cumsum(np.abs(np.diff(rec.target, prepend=rec.target[0])))


@dataclass(frozen=True)
class Structure:
    """Structure outside the vocabulary, added to a synthetic recording.

    ``amplitude`` is its peak contribution (deviation units): a step's height, a
    curvature's largest departure, a periodic error's peak, a hysteresis' reversal
    at the end of the travel (or of the campaign).  Variants:

    * step: ``amplitude`` beyond ``position``, 0 before (a grating segment joint);
    * curvature: over the travel ``span`` with u in [-1, 1]: ``quadratic`` u^2 (no
      linear part), ``quadratic_from_zero`` (x / L)^2 (with one), ``cubic`` the
      Legendre P3 (no linear part), ``cubic_from_zero`` u^3 (with one),
      ``quadratic_cubic`` 0.6 u^2 + 0.4 u^3; scaled to peak ``amplitude``;
    * nonsine_periodic of ``period`` and ``phase`` (fraction of a period):
      ``sawtooth``, ``triangle``, ``square`` (tanh(4 sin), harmonics 3, 5, ...);
    * growing_hysteresis: a reversal growing from 0 ``with_position`` along the
      travel, or ``with_distance`` travelled since the campaign began.
    """

    kind: str
    variant: str
    amplitude: float
    position: float = 0.0
    period: float = 0.0
    phase: float = 0.0
    span: tuple[float, float] = Z_TRAVEL_MM

    def evaluate(self, rec: Recording) -> np.ndarray:
        x = rec.target.astype(float)
        lo, hi = self.span
        a = self.amplitude
        if self.kind == "step":
            return np.where(x >= self.position, a, 0.0)
        if self.kind == "curvature":
            u = (2 * x - lo - hi) / (hi - lo)
            f = {"quadratic": u ** 2, "quadratic_from_zero": ((x - lo) / (hi - lo)) ** 2,
                 "cubic": (5 * u ** 3 - 3 * u) / 2, "cubic_from_zero": u ** 3,
                 "quadratic_cubic": 0.6 * u ** 2 + 0.4 * u ** 3}[self.variant]
            return a * f
        if self.kind == "nonsine_periodic":
            z = x / self.period + self.phase
            saw = 2 * (z - np.floor(z + 0.5))
            f = {"sawtooth": saw, "triangle": 2 * np.abs(saw) - 1,
                 "square": np.tanh(4 * np.sin(2 * np.pi * z)) / np.tanh(4)}[self.variant]
            return a * f
        if self.kind == "growing_hysteresis":
            s = rec.direction.astype(float)
            if self.variant == "with_position":
                g = (x - lo) / (hi - lo)
            else:
                d = distance_travelled(rec)
                g = d / max(d[-1], 1e-12)
            return s * a * g / 2.0
        raise ValueError(f"unknown structure kind {self.kind!r}")

    @property
    def where(self) -> str:
        if self.kind == "step":
            return f"{self.amplitude:+.3g} at {self.position:.4g}"
        if self.kind == "nonsine_periodic":
            return f"{self.variant} period {self.period:.4g} peak {self.amplitude:.3g}"
        return f"{self.variant} peak {self.amplitude:.3g}"


def with_structure(rec: Recording, structure: Structure) -> Recording:
    """Add ``structure`` to the recording's deviation (in place, rounded as recorded); returns it."""
    rec.deviation = np.round(rec.deviation + structure.evaluate(rec), 4)
    return rec
