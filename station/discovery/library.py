"""The library of physics discovery may propose, and how each candidate is tried.

The formulas are those of :mod:`station.effects` (one definition per effect);
this module only adds effects the contract's vocabulary lacks (registered with
:func:`station.effects.register`, so a model file that names them can be read
by the twin too) and, for every candidate, what is fitted, from where the fit
starts, what is physical, and how many hypotheses a scan tries (for the
multiple-testing correction of its p-value).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable, ClassVar

import numpy as np

from station.effects import (
    ABBE_CHANNEL, AbbeError, Backlash, Eccentricity, Effect, EvalContext, LocalDefect, Offset, Periodic, Scale,
    Step, ThermalDrift, ThermalExpansion,
)
from station.discovery.data import Prepared


def local_defect_grid(prep: Prepared) -> tuple[np.ndarray, np.ndarray]:
    """Centres and widths of the local-defect scan, as flat arrays of equal length.

    For each width, centres every half width (a Gaussian sampled at half its width
    is never missed by more than ~3 % of its peak), on distinct targets when they
    are sparser, capped at ``MAX_CENTRES_PER_WIDTH`` so a 10^4-point recording
    stays fast.  The number of pairs is the scan's Bonferroni count.
    """
    targets = distinct_targets(prep)
    lo, hi = float(targets[0]), float(targets[-1])
    cs, ws = [], []
    for w in width_grid(prep):
        step = max(w / 2.0, (hi - lo) / MAX_CENTRES_PER_WIDTH)
        centres = np.arange(lo, hi + 1e-12, step) if targets.size * step > (hi - lo) else targets
        cs.append(centres)
        ws.append(np.full(centres.size, w))
    return np.concatenate(cs), np.concatenate(ws)


def local_defect_columns(prep: Prepared, centres: np.ndarray, widths: np.ndarray) -> np.ndarray:
    """Unit-amplitude bumps at every (centre, width): the class's own formula, broadcast."""
    ctx = EvalContext.make(prep.x[:, None], prep.kind)
    return LocalDefect(centres[None, :], widths[None, :], 1.0).evaluate(ctx)


#: centres tried per width in the local-defect scan (speed bound, see local_defect_grid)
MAX_CENTRES_PER_WIDTH = 120

#: distinct targets a step needs on each side: a jump before the last target alone is
#: one point off (an outlier or a local defect), not a joint between two segments
MIN_STEP_SIDE = 2
#: positions tried at once in the step scan (speed bound on dense recordings; the
#: best one is then refined over every gap near it, see select.refine_steps)
MAX_STEP_POSITIONS = 240


def step_gaps(prep: Prepared) -> tuple[np.ndarray, np.ndarray]:
    """The gaps a step may sit in: (left target, right target) of consecutive distinct
    targets with at least ``MIN_STEP_SIDE`` distinct targets on each side.

    A step between two targets fits the data equally well anywhere in the gap, so
    the gap is what the recording resolves: the step is placed at its middle and
    its position uncertainty covers it (select.refine_steps).
    """
    t = distinct_targets(prep)
    if t.size < 2 * MIN_STEP_SIDE:
        return np.empty(0), np.empty(0)
    left, right = t[:-1], t[1:]
    keep = slice(MIN_STEP_SIDE - 1, t.size - MIN_STEP_SIDE)
    return left[keep], right[keep]


def step_grid(prep: Prepared) -> np.ndarray:
    """Step positions of the scan: gap middles, thinned to ``MAX_STEP_POSITIONS``."""
    left, right = step_gaps(prep)
    mids = (left + right) / 2.0
    if mids.size > MAX_STEP_POSITIONS:
        mids = mids[:: int(np.ceil(mids.size / MAX_STEP_POSITIONS))]
    return mids


def step_columns(prep: Prepared, positions: np.ndarray) -> np.ndarray:
    """Unit steps at every position: the class's own formula, broadcast."""
    ctx = EvalContext.make(prep.x[:, None], prep.kind)
    return Step(positions[None, :], 1.0).evaluate(ctx).astype(float)


#: Effects registered by discovery (documented in docs/discovery.md).
EXTRA_EFFECTS = (LocalDefect, Step)


@dataclass
class Candidate:
    """How one effect is tried as an addition to the current model.

    ``inits`` returns starting effects (one per scanned value of the nonlinear
    parameters); ``trials`` is the number of hypotheses the scan behind it tests
    and ``df_single`` the degrees of freedom of one of them, so the p-value of the
    best is ``min(1, trials * P(chi2_df_single > LR))`` (Bonferroni over the scan).
    """

    name: str
    free: tuple[str, ...]
    inits: Callable[[Prepared], list[Effect]]
    magnitude: str
    trials: float = 1.0
    df_single: int = 1
    bounds: dict[str, tuple[float, float]] = field(default_factory=dict)
    physical: Callable[[Effect, Prepared], str | None] = lambda e, p: None

    @property
    def n_params(self) -> int:
        return len(self.free)


def distinct_targets(prep: Prepared) -> np.ndarray:
    return np.unique(np.round(prep.x, 6))


def min_spacing(prep: Prepared) -> float:
    """Smallest step between distinct targets (5th percentile, robust to a near-duplicate)."""
    t = distinct_targets(prep)
    if t.size < 2:
        return 0.0
    gaps = np.diff(t)
    return float(np.percentile(gaps, 5))


def period_limits(prep: Prepared) -> tuple[float, float]:
    """Shortest and longest period a periodic effect may have in this recording.

    Shortest: two target steps (the Nyquist-like limit of the finest spacing, x1.1
    margin against the very edge).  Longest: two thirds of the travel, so that at
    least 1.5 cycles are seen; anything longer is a trend or curvature, and on a
    rotary axis once-per-revolution belongs to eccentricity.
    """
    rng = float(np.ptp(prep.x))
    p_min = 2.2 * min_spacing(prep)
    p_max = rng / 1.5
    if prep.kind == "rotary":
        p_max = min(p_max, 360.0 / 1.5)
    return p_min, p_max


def tau_grid(prep: Prepared) -> np.ndarray:
    """Time constants tried for thermal drift: 1/30 to 5 times the campaign length.

    Faster than 1/30 of the campaign a warm-up is over before the second target;
    slower than five campaign lengths it is a straight line and its amplitude and
    tau cannot be told apart.
    """
    span = float(np.ptp(prep.time_s))
    return np.geomspace(span / 30.0, 5.0 * span, 12)


def width_grid(prep: Prepared) -> np.ndarray:
    """Widths tried for a local defect: from the finest spacing to 1/12 of the travel."""
    lo = max(min_spacing(prep), 1e-6)
    hi = max(np.ptp(prep.x) / 12.0, 1.5 * lo)
    return np.geomspace(lo, hi, 5)


def _phys_periodic(e: Periodic, prep: Prepared) -> str | None:
    p_min, p_max = period_limits(prep)
    if not (p_min <= e.period <= p_max):
        return f"period {e.period:.4g} outside the resolvable range [{p_min:.4g}, {p_max:.4g}]"
    return None


def _phys_drift(e: ThermalDrift, prep: Prepared) -> str | None:
    span = float(np.ptp(prep.time_s))
    if e.tau <= 0:
        return f"tau = {e.tau:.4g} s is not positive"
    # the warm-up must be observed: at the fifth reading at least half of it is
    # still to come; otherwise it is carried by a handful of early points and is,
    # for the rest of the data, an offset
    times = np.sort(prep.time_s)
    t5 = float(times[min(4, times.size - 1)])
    seen = float(np.exp(-t5 / e.tau))
    if seen < 0.5:
        return (f"tau = {e.tau:.4g} s: only {seen:.0%} of the drift happens after the fifth reading "
                f"(t = {t5:.4g} s); that is an offset")
    if e.tau > 10 * span:
        return f"tau = {e.tau:.4g} s is over ten campaign lengths: a straight drift, amplitude and tau not separable"
    return None


def _phys_local(e: LocalDefect, prep: Prepared) -> str | None:
    lo, hi = float(prep.x.min()), float(prep.x.max())
    if not (lo <= e.centre <= hi):
        return f"centre {e.centre:.4g} outside the measured range"
    w = abs(e.width)
    inside = np.count_nonzero(np.abs(distinct_targets(prep) - e.centre) <= 2 * w)
    if inside < 3:
        return f"only {inside} targets within +-2 widths of the centre: not resolved"
    if w > np.ptp(prep.x) / 6:
        return "wider than a sixth of the travel: not local (a trend or curvature)"
    return None


def _phys_step(e: Step, prep: Prepared) -> str | None:
    t = distinct_targets(prep)
    below = int(np.count_nonzero(t < e.position))
    above = int(np.count_nonzero(t >= e.position))
    if min(below, above) < MIN_STEP_SIDE:
        return (f"only {min(below, above)} distinct target(s) on one side of {e.position:.4g}: "
                "an end point off, not a joint between segments")
    return None


def candidates(prep: Prepared, exclude: set[str] = frozenset()) -> list[Candidate]:
    """The candidates this recording can support (channels and kind permitting)."""
    out: list[Candidate] = [
        Candidate("offset", ("value",), lambda p: [Offset(0.0)], "value"),
        Candidate("scale", ("ppm",), lambda p: [Scale(0.0)], "ppm"),
    ]
    if np.unique(prep.direction).size == 2:
        out.append(Candidate("backlash", ("reversal",), lambda p: [Backlash(0.0)], "reversal"))
    if prep.time_s is not None:
        span = float(np.ptp(prep.time_s))
        grid = tau_grid(prep)
        out.append(Candidate(
            "thermal_drift", ("amplitude", "tau"),
            lambda p, g=grid: [ThermalDrift(1.0, float(t)) for t in g], "amplitude",
            trials=float(grid.size), df_single=1,
            bounds={"tau": (span / 100.0, 20.0 * span)}, physical=_phys_drift))
    if prep.temperature_c is not None and np.ptp(prep.temperature_c) >= 0.1:
        out.append(Candidate("thermal_expansion", ("coefficient",),
                             lambda p: [ThermalExpansion(0.0, 20.0)], "coefficient"))
    if prep.kind == "rotary" and np.ptp(prep.x) >= 180.0:
        # at least half a revolution is needed to see a once-per-revolution sine
        out.append(Candidate("eccentricity", ("amplitude", "phase"),
                             lambda p: [Eccentricity(1.0, 0.0), Eccentricity(1.0, np.pi / 2)], "amplitude",
                             df_single=2))
    p_min, p_max = period_limits(prep)
    if p_min > 0 and p_max > p_min:
        span = float(np.ptp(prep.x))
        # independent frequencies between 1/p_max and 1/p_min (Horne & Baliunas 1986:
        # about the number of Fourier frequencies in the band)
        m = max(1.0, span * (1.0 / p_min - 1.0 / p_max))
        out.append(Candidate("periodic", ("period", "amplitude", "phase"), None, "amplitude",
                             trials=m, df_single=2,
                             bounds={"period": (p_min, p_max)}, physical=_phys_periodic))
    if distinct_targets(prep).size >= 8:
        widths = width_grid(prep)
        n_grid = local_defect_grid(prep)[0].size
        out.append(Candidate("local_defect", ("centre", "width", "amplitude"), None, "amplitude",
                             trials=float(n_grid), df_single=1,
                             bounds={"width": (0.5 * widths[0], 2.0 * widths[-1]),
                                     "centre": (float(prep.x.min()), float(prep.x.max()))},
                             physical=_phys_local))
    n_gaps = step_gaps(prep)[0].size
    if prep.kind in Step.kinds and n_gaps >= 1:
        # the position is scanned over the gaps (not fitted: the misfit is flat within a
        # gap and jumps between gaps), the height is linear; Bonferroni over the gaps
        out.append(Candidate("step", ("height",), None, "height", trials=float(n_gaps), df_single=1,
                             physical=_phys_step))
    angle = prep.channels.get(ABBE_CHANNEL)
    if prep.kind == "linear" and angle is not None and np.ptp(angle) > 0:
        # linear in the arm: one parameter, no scan
        out.append(Candidate("abbe", ("arm_mm",), lambda p: [AbbeError(0.0)], "arm_mm",
                             physical=_phys_abbe))
    return [c for c in out if c.name not in exclude]


#: an Abbe offset longer than this is not an offset on this station but a sign that the
#: angle column is not the angle of this axis (the whole machine is under a metre)
MAX_ABBE_ARM_MM = 1000.0


def _phys_abbe(e: AbbeError, prep: Prepared) -> str | None:
    if abs(e.arm_mm) > MAX_ABBE_ARM_MM:
        return f"an Abbe offset of {e.arm_mm:.0f} mm is longer than the machine"
    return None


#: the measurement that separates two effects that this recording cannot tell apart
SEPARATING_MEASUREMENT = {
    frozenset({"backlash", "thermal_drift"}):
        "a run in reversed order (approach -1 first, then +1) or pilgrim-step runs, with the "
        "temperature logged: backlash keeps its sign with the direction, drift follows time",
    frozenset({"scale", "thermal_expansion"}):
        "a campaign at another temperature, or temperature logging through a warm-up: a scale "
        "error does not change with temperature, thermal expansion does",
    frozenset({"offset", "thermal_drift"}):
        "a longer campaign started from a cold machine, so the drift is seen to settle",
    frozenset({"eccentricity", "periodic"}):
        "a full-revolution recording with finer angular steps",
    frozenset({"periodic", "local_defect"}):
        "dense short-step runs over the whole travel: a periodic error repeats, a defect does not",
    frozenset({"scale", "periodic"}):
        "targets spread over the whole travel with finer steps",
    frozenset({"scale", "local_defect"}):
        "dense short-step runs over the whole travel",
    frozenset({"scale", "thermal_drift"}):
        "a run in reversed target order: a scale error follows position, drift follows time",
    frozenset({"offset", "scale"}):
        "targets nearer the travel's zero",
    frozenset({"abbe", "scale"}):
        "a second run with the reflector at another height: the Abbe error scales with the "
        "offset, a scale error does not",
    frozenset({"step", "local_defect"}):
        "dense short-step runs across the suspected joint: a step stays beyond it, a defect returns",
    frozenset({"step", "scale"}):
        "targets spaced more finely along the whole travel: a scale error grows evenly, a joint jumps",
    frozenset({"step", "offset"}):
        "more targets near the travel's start: an offset is there too, a joint's jump is not",
    frozenset({"step", "periodic"}):
        "dense short-step runs over the whole travel: a periodic error repeats, a joint jumps once",
    frozenset({"abbe", "periodic"}):
        "a second run with the reflector at another height: the Abbe error scales with the "
        "offset, a periodic error of the scale does not",
}


def separating_measurement(a: str, b: str) -> str:
    return SEPARATING_MEASUREMENT.get(
        frozenset({a, b}),
        "more runs with the targets visited in a different order, and the temperature logged")
