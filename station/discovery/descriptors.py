"""Descriptions of structure *outside* the vocabulary, so that no effect is claimed for it.

Why?  Forward selection offers only the vocabulary, and a vocabulary can absorb
structure it does not describe: a step in the scale looks, to a least-squares fit,
like a scale error plus a long-period sine; a parabola like an offset plus part of
a sine; a sawtooth like a sine at its fundamental; a reversal that grows along the
travel like a constant backlash of its mean.  Each such claim passes every gate
(the structure is real and repeats from run to run) and is still wrong: it would go
into the twin and into compensation as an effect that is not there.

The remedy (issue 20) is a *flexible nuisance* beside the vocabulary: for each
family of structure the vocabulary speaks about, a more flexible description that
contains the vocabulary's effects of that family as special cases --

* ``curvature``: a polynomial of degree 2 to 4 in position (Legendre basis over the
  travel), containing ``offset`` and ``scale``;
* ``periodic_shape``: a Fourier series of 2 to 12 harmonics of one period (as many as
  the targets resolve), containing ``periodic`` (a single sine) at that period; the
  period is found by string length, which a sharp feature does not fool;
* ``hysteresis``: a reversal that changes linearly along the travel, over the
  campaign, or both, containing ``backlash`` (a constant reversal).

Descriptors are offered to the selection like any candidate and must pass the same
gates (BIC, scan-corrected likelihood ratio, cross-validation by run), and must
out-explain the effects they contain, fitted as well as the vocabulary can
(:mod:`station.discovery.select`).  A vocabulary effect therefore has to out-explain
its own generalisation to be claimed: when the data show the structure to be more
than the effect (harmonics of a periodic error, a reversal that varies, a bend), the
descriptor wins, the effects it contains are taken out of the model (they cannot be
told from the descriptor's own parts -- the mean and slope of a curvature *are* an
offset and a scale error) and are not offered while it is there, and every other
effect must be significant beside it, also against the descriptor's *saturated*
form (:meth:`Descriptor.saturated_columns`).  A descriptor is never claimed as an
effect: it becomes a located, described finding and the verdict is
``partly-explained``; it is never written to a model file.

Descriptors are linear in their coefficients (the period of ``periodic_shape`` moves
only a little in the joint fit), and the normalisation of position and time is fixed
when they are built, so a fit never moves it.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from station.effects import Effect, EvalContext, Periodic

#: highest polynomial degree tried for a curvature (degree 2 and 3 are the issue's
#: curvature; 4 covers an S- or W-shaped bend without reaching for a spline)
MAX_CURVATURE_DEGREE = 4
#: phase bins of the saturated periodic profile, at most (select.check_beside_descriptors)
MAX_PROFILE_BINS = 64
#: harmonics of a non-sinusoidal periodic error, at most (fewer when the targets
#: cannot resolve them: period / k >= the shortest resolvable period).  A sawtooth's
#: harmonics fall off only as 1/k, so a strong one needs many: beyond the 12th they
#: carry under 5 % of its power
MAX_HARMONICS = 12


def _unit(v, lo: float, hi: float):
    """Map [lo, hi] onto [-1, 1] (the Legendre interval)."""
    return (2.0 * np.asarray(v, dtype=float) - lo - hi) / max(hi - lo, 1e-12)


def _legendre(u, degree: int) -> list[np.ndarray]:
    """P_0 .. P_degree at ``u`` (Bonnet's recursion)."""
    p = [np.ones_like(u), u]
    for n in range(1, degree):
        p.append(((2 * n + 1) * u * p[n] - n * p[n - 1]) / (n + 1))
    return p[: degree + 1]


class Descriptor(Effect):
    """Base of the descriptors: effects discovery may fit but never claims."""

    #: the report's signature of the finding it becomes
    signature: ClassVar[str] = "position"
    #: names of the vocabulary effects it contains (taken out of the model with it)
    contains: ClassVar[tuple[str, ...]] = ()
    #: vocabulary effects not offered while it is in the model: those it contains (they
    #: are collinear with it: offset and scale with a curvature, backlash with a varying
    #: reversal) and those that cannot be told from what it leaves (see PeriodicShape)
    bars: ClassVar[tuple[str, ...]] = ()

    @classmethod
    def barred(cls) -> tuple[str, ...]:
        return tuple(dict.fromkeys(cls.contains + cls.bars))

    def subsumes(self, effect: Effect, span: float) -> bool:
        """Whether ``effect`` is one of this descriptor's special cases (taken out with it)."""
        return effect.name in self.contains

    def finding(self, prep, unit: tuple[str, str]) -> dict:  # pragma: no cover - abstract
        raise NotImplementedError

    def saturated_columns(self, prep) -> np.ndarray | None:
        """The most flexible description of this family the recording supports, as
        regression columns, or None when the descriptor is already that (see
        select.check_beside_descriptors)."""
        return None


@dataclass(frozen=True)
class Curvature(Descriptor):
    """``sum_k c_k P_k(u)``, u = position mapped onto [-1, 1] over the measured travel."""

    lo: float = 0.0
    hi: float = 1.0
    c0: float = 0.0
    c1: float = 0.0
    c2: float = 0.0
    c3: float = 0.0
    c4: float = 0.0
    name: ClassVar[str] = "curvature"
    signature: ClassVar[str] = "position"
    contains: ClassVar[tuple[str, ...]] = ("offset", "scale")
    explanation: ClassVar[str] = "a bend of the error along the travel that no vocabulary effect describes"

    def evaluate(self, ctx):
        p = _legendre(_unit(ctx.x, self.lo, self.hi), MAX_CURVATURE_DEGREE)
        c = (self.c0, self.c1, self.c2, self.c3, self.c4)
        return sum(ck * pk for ck, pk in zip(c, p))

    def saturated_columns(self, prep) -> np.ndarray:
        """The polynomial of the highest degree tried, whatever degree was chosen."""
        return np.column_stack(_legendre(_unit(prep.x, self.lo, self.hi), MAX_CURVATURE_DEGREE))

    def finding(self, prep, unit):
        du, pu = unit
        xs = np.linspace(self.lo, self.hi, 241)
        y = self.evaluate(EvalContext.make(xs, prep.kind))
        line = np.polyval(np.polyfit(xs, y, 1), xs)
        bend = y - line
        lo_k, hi_k = int(np.argmin(bend)), int(np.argmax(bend))
        degree = max([d for d, c in enumerate((self.c0, self.c1, self.c2, self.c3, self.c4)) if c != 0.0] or [0])
        slope = float(y[-1] - y[0])
        return {
            "range": [float(self.lo), float(self.hi)], "direction": "both",
            "description": (
                f"curvature along the travel not in the vocabulary: the error departs from a straight line "
                f"by {bend[lo_k]:+.3g} {du} near {xs[lo_k]:.4g} {pu} to {bend[hi_k]:+.3g} {du} near "
                f"{xs[hi_k]:.4g} {pu} (a degree-{degree} polynomial fits it; {slope:+.3g} {du} from "
                f"{self.lo:.4g} to {self.hi:.4g} {pu}); no offset or scale error is claimed, since they "
                f"cannot be told from the curvature's own mean and slope"),
        }


@dataclass(frozen=True)
class PeriodicShape(Descriptor):
    """``sum_k a_k sin(2 pi k x / period) + b_k cos(2 pi k x / period)``, k = 1 .. 12."""

    period: float = 1.0
    a1: float = 0.0
    b1: float = 0.0
    a2: float = 0.0
    b2: float = 0.0
    a3: float = 0.0
    b3: float = 0.0
    a4: float = 0.0
    b4: float = 0.0
    a5: float = 0.0
    b5: float = 0.0
    a6: float = 0.0
    b6: float = 0.0
    a7: float = 0.0
    b7: float = 0.0
    a8: float = 0.0
    b8: float = 0.0
    a9: float = 0.0
    b9: float = 0.0
    a10: float = 0.0
    b10: float = 0.0
    a11: float = 0.0
    b11: float = 0.0
    a12: float = 0.0
    b12: float = 0.0
    name: ClassVar[str] = "periodic_shape"
    signature: ClassVar[str] = "periodic"
    contains: ClassVar[tuple[str, ...]] = ("periodic",)
    #: a finite series leaves, at the error's sharp features (a sawtooth's jump, a square
    #: wave's edges), misfits in every period, and far from where the period is best
    #: measured its phase is uncertain at those features: there a further sine (a harmonic
    #: above the resolvable period, or its alias on the targets' grid), a local defect or
    #: a step would be taking up the periodic error, not describing something else
    bars: ClassVar[tuple[str, ...]] = ("local_defect", "step")
    explanation: ClassVar[str] = "an error that repeats with position but is not a sine"

    def coefficients(self) -> np.ndarray:
        """(a_k, b_k) for k = 1 .. MAX_HARMONICS, shape (MAX_HARMONICS, 2)."""
        return np.array([[getattr(self, f"a{k}"), getattr(self, f"b{k}")] for k in range(1, MAX_HARMONICS + 1)])

    def evaluate(self, ctx):
        w = 2.0 * np.pi * ctx.x / self.period
        out = np.zeros_like(ctx.x)
        for k, (a, b) in enumerate(self.coefficients(), start=1):
            if a or b:
                out = out + a * np.sin(k * w) + b * np.cos(k * w)
        return out

    def subsumes(self, effect: Effect, span: float) -> bool:
        """A periodic effect at a harmonic of this shape's period (within the frequency
        resolution of the travel, 0.5 / span), fitted or not, is part of it; one at
        another period is not."""
        if not isinstance(effect, Periodic) or span <= 0:
            return False
        f = 1.0 / abs(effect.period)
        k = max(1, round(f * self.period))
        return bool(abs(f - k / self.period) <= 0.5 / span)

    def saturated_columns(self, prep) -> np.ndarray:
        """Any piecewise-linear function of the phase ``x / period mod 1`` (a level and a
        slope per phase bin), with the period free.

        A sharp feature (the jump of a sawtooth, the edges of a square wave) needs more
        harmonics than any series fits, and what the series leaves is concentrated at
        that feature, in every period: in the residual it looks like a local defect, a
        step or another sine.  Binning the phase catches it whatever its shape, a slope
        per bin the ramps between (bins: :func:`profile_bins`).
        """
        b = profile_bins(prep.x)
        # a bin edge at the shape's steepest point (a sawtooth's jump, a square wave's
        # edge), so that no bin straddles it
        grid = np.linspace(0.0, 1.0, 720, endpoint=False)
        y = self.evaluate(EvalContext.make(grid * self.period, prep.kind))
        edge = grid[int(np.argmax(np.abs(np.diff(np.r_[y, y[0]]))))] + 0.5 / 720
        phase = np.mod(prep.x / self.period - edge, 1.0)
        idx = np.minimum((phase * b).astype(int), b - 1)
        rows = np.arange(prep.n)
        level = np.zeros((prep.n, b))
        level[rows, idx] = 1.0
        slope = np.zeros((prep.n, b))
        slope[rows, idx] = phase * b - idx - 0.5
        # and the period free, linearised: a small error dP of the period shifts the phase
        # by -x dP / P^2, so the profile f moves by -f'(phase) x dP / P^2: with f' free per
        # bin, a column x per bin (for a sawtooth, whose f' is one constant, that is a
        # scale error: the two cannot be told apart)
        cols = np.column_stack([level, slope, level * (prep.x - prep.x.mean())[:, None]])
        return cols[:, np.ptp(cols, axis=0) > 0]

    def finding(self, prep, unit):
        du, pu = unit
        c = self.coefficients()
        power = np.sum(c ** 2, axis=1)
        harm = float(power[1:].sum() / power.sum()) if power.sum() > 0 else 0.0
        xs = np.linspace(0.0, self.period, 400, endpoint=False)
        y = self.evaluate(EvalContext.make(xs, prep.kind))
        return {
            "range": [float(prep.x.min()), float(prep.x.max())], "direction": "both",
            "period": float(self.period),
            "description": (
                f"non-sinusoidal periodic error not in the vocabulary: period {self.period:.4g} {pu}, "
                f"{np.ptp(y):.3g} {du} peak to peak, {harm:.0%} of its power in harmonics 2 to "
                f"{int(np.max(np.nonzero(power)[0])) + 1}; the vocabulary's periodic (one sine) does not describe "
                f"it, so no periodic effect is claimed"),
        }


@dataclass(frozen=True)
class Hysteresis(Descriptor):
    """``s / 2 * reversal(x, t)``: the reversal a function of the position u and of the
    campaign's time v (both mapped onto [-1, 1]); the selection fits its linear terms,
    the quadratic ones are part of its saturated form."""

    x_lo: float = 0.0
    x_hi: float = 1.0
    t_lo: float = 0.0
    t_hi: float = 1.0
    h0: float = 0.0
    hx: float = 0.0
    hx2: float = 0.0
    ht: float = 0.0
    ht2: float = 0.0
    name: ClassVar[str] = "hysteresis"
    signature: ClassVar[str] = "direction"
    contains: ClassVar[tuple[str, ...]] = ("backlash",)
    explanation: ClassVar[str] = "a reversal that changes along the travel or over the campaign"

    def reversal(self, x, t=None):
        u = _unit(x, self.x_lo, self.x_hi)
        rev = self.h0 + self.hx * u + self.hx2 * (1.5 * u * u - 0.5)
        if t is not None and (self.ht or self.ht2):
            v = _unit(t, self.t_lo, self.t_hi)
            rev = rev + self.ht * v + self.ht2 * (1.5 * v * v - 0.5)
        return rev

    def evaluate(self, ctx):
        s = np.zeros_like(ctx.x) if ctx.direction is None else ctx.direction
        return s * self.reversal(ctx.x, ctx.time_s) / 2.0

    def saturated_columns(self, prep) -> np.ndarray:
        """The reversal's every term (linear and quadratic in position and, with
        trustworthy time stamps, in time), whichever were chosen."""
        half_s = prep.direction / 2.0
        u = _unit(prep.x, self.x_lo, self.x_hi)
        cols = [half_s, half_s * u, half_s * (1.5 * u * u - 0.5)]
        if prep.time_s is not None and self.t_hi > self.t_lo:
            v = _unit(prep.time_s, self.t_lo, self.t_hi)
            cols += [half_s * v, half_s * (1.5 * v * v - 0.5)]
        return np.column_stack(cols)

    def finding(self, prep, unit):
        du, pu = unit
        parts = []
        if self.hx or self.hx2:
            xs = np.linspace(self.x_lo, self.x_hi, 121)
            r = self.reversal(xs)
            parts.append(f"from {r[0]:+.3g} {du} at {self.x_lo:.4g} {pu} to {r[-1]:+.3g} {du} at "
                         f"{self.x_hi:.4g} {pu} (between {r.min():+.3g} and {r.max():+.3g})")
        if self.ht or self.ht2:
            v = np.array([-1.0, 1.0])
            r = self.h0 + self.ht * v + self.ht2 * (1.5 * v * v - 0.5)
            parts.append(f"from {r[0]:+.3g} {du} at the start of the campaign to {r[1]:+.3g} {du} at its end")
        return {
            "range": [float(prep.x.min()), float(prep.x.max())], "direction": "both",
            "description": (
                "hysteresis not in the vocabulary: the reversal (approach +1 minus -1) is not constant, it "
                "goes " + " and ".join(parts) + "; a constant backlash does not describe it, so none is claimed"),
        }


DESCRIPTORS = (Curvature, PeriodicShape, Hysteresis)


def is_descriptor(e: Effect) -> bool:
    return isinstance(e, Descriptor)


# ------------------------------------------------------------------ how each descriptor is tried

@dataclass
class Proposal:
    """A descriptor offered to the selection: the current terms that stay, the new
    term, and what the likelihood-ratio test of it is corrected for."""

    name: str
    keep: list            # current Terms that stay
    removed: list         # current Terms it contains (taken out with it)
    term: object          # the descriptor's Term
    df: int               # free parameters it adds beyond those it takes out (the scanned period excepted)
    trials: float         # hypotheses behind it: scanned periods x variants tried


def _whitened_lstsq(W, cols: np.ndarray, r: np.ndarray, nuisance: np.ndarray | None = None):
    """Coefficients of ``cols`` and the whitened RSS of ``r ~ cols (+ nuisance)``.

    By the normal equations (a few dozen columns against up to 10^4 rows: the Gram
    matrix is small and well conditioned for these bases), pseudo-inverse if singular.
    """
    a = cols if nuisance is None else np.column_stack([cols, nuisance])
    aw, rw = W(a), W(r)
    g, b = aw.T @ aw, aw.T @ rw
    try:
        coef = np.linalg.solve(g, b)
    except np.linalg.LinAlgError:
        coef = np.linalg.pinv(g) @ b
    res = rw - aw @ coef
    return coef[: cols.shape[1]], float(res @ res)


def _best_variant(W, r: np.ndarray, variants: list[tuple[tuple[str, ...], np.ndarray]], n: int):
    """The variant (names, columns) with the lowest BIC on ``r``, its coefficients."""
    best = None
    for names, cols in variants:
        coef, rss = _whitened_lstsq(W, cols, r)
        b = n * np.log(max(rss, 1e-300) / n) + len(names) * np.log(n)
        if best is None or b < best[0]:
            best = (b, names, coef)
    return best[1], best[2]


def _split(terms, descriptor: Descriptor, span: float):
    keep = [t for t in terms if not descriptor.subsumes(t.effect, span)]
    removed = [t for t in terms if descriptor.subsumes(t.effect, span)]
    return keep, removed


def _contribution(terms, ctx) -> np.ndarray:
    out = np.zeros_like(ctx.x)
    for t in terms:
        out = out + t.effect.evaluate(ctx)
    return out


def init_curvature(prep, W, terms, r_cur, term_cls):
    t = np.unique(np.round(prep.x, 6))
    max_deg = min(MAX_CURVATURE_DEGREE, t.size - 3)
    if max_deg < 2:
        return None
    lo, hi = float(t[0]), float(t[-1])
    proto = Curvature(lo, hi)
    span = hi - lo
    keep, removed = _split(terms, proto, span)
    ctx = prep.ctx()
    r = r_cur + _contribution(removed, ctx)
    p = _legendre(_unit(prep.x, lo, hi), max_deg)
    names = ("c0", "c1", "c2", "c3", "c4")
    variants = [(names[: d + 1], np.column_stack(p[: d + 1])) for d in range(2, max_deg + 1)]
    free, coef = _best_variant(W, r, variants, prep.n)
    e = Curvature(lo, hi, **{k: float(v) for k, v in zip(free, coef)})
    k_removed = sum(len(u.free) for u in removed)
    return Proposal("curvature", keep, removed, term_cls(e, free), len(free) - k_removed, float(len(variants)))


def init_hysteresis(prep, W, terms, r_cur, term_cls):
    if np.unique(prep.direction).size < 2:
        return None
    x_lo, x_hi = float(prep.x.min()), float(prep.x.max())
    has_t = prep.time_s is not None and np.ptp(prep.time_s) > 0
    t_lo, t_hi = (float(prep.time_s.min()), float(prep.time_s.max())) if has_t else (0.0, 1.0)
    proto = Hysteresis(x_lo, x_hi, t_lo, t_hi)
    keep, removed = _split(terms, proto, x_hi - x_lo)
    ctx = prep.ctx()
    r = r_cur + _contribution(removed, ctx)
    half_s = prep.direction / 2.0
    u = _unit(prep.x, x_lo, x_hi)
    col = {"h0": half_s, "hx": half_s * u, "hx2": half_s * (1.5 * u * u - 0.5)}
    # a reversal growing along the travel, over the campaign (with the distance travelled,
    # the wear or the warm-up of the drive), or both; linear: a growth of any monotone
    # shape is mostly its linear part, and every variant tried costs power (Bonferroni)
    sets = [("h0", "hx")]
    if has_t:
        v = _unit(prep.time_s, t_lo, t_hi)
        col.update({"ht": half_s * v})
        sets += [("h0", "ht"), ("h0", "hx", "ht")]
    variants = [(s, np.column_stack([col[k] for k in s])) for s in sets]
    free, coef = _best_variant(W, r, variants, prep.n)
    e = Hysteresis(x_lo, x_hi, t_lo, t_hi, **{k: float(v) for k, v in zip(free, coef)})
    k_removed = sum(len(u_.free) for u_ in removed)
    return Proposal("hysteresis", keep, removed, term_cls(e, free), len(free) - k_removed, float(len(variants)))


#: the period of a non-sinusoidal shape is refined on this many trial periods within
#: +-1 / span in frequency of the starting one (the sine scan's peak, which the shape's
#: harmonics and their aliases pull), by string length (:func:`string_length`); the
#: joint fit then moves it by at most ``PERIOD_FIT_RANGE`` / span in frequency (a
#: truncated series would pull it towards fitting the points next to a jump, at the
#: cost of a drift of phase along the travel that a scale error then takes up)
PERIOD_REFINE_POINTS = 401
PERIOD_FIT_RANGE = 0.01


def string_length(x: np.ndarray, r: np.ndarray, period: float) -> float:
    """Sum of squared steps between neighbours in phase order (``x / period mod 1``,
    round the circle), less the best straight line in position: the string-length
    period search (Lafler & Kinman 1965, Dworetsky 1983) for a periodic signal of
    *any* shape.

    At the true period neighbours in phase are close in value, except across a sharp
    feature, which costs one step per jump, not one per point (a least-squares series
    or a binned profile misfits every point near a jump, and its best period is pulled
    by them); at a wrong period the order is scrambled.  A trend ``b x`` adds
    ``b dx`` to each step, so the best ``b`` is removed in closed form
    (``sum(dv dx) / sum(dx^2)``): a scale error in the residual does not move the period.
    O(n log n) per trial period.
    """
    order = np.argsort(np.mod(x / period, 1.0), kind="stable")
    v, xs = r[order], x[order]
    dv = np.diff(np.r_[v, v[0]])
    dx = np.diff(np.r_[xs, xs[0]])
    sxx = float(dx @ dx)
    b = float(dv @ dx) / sxx if sxx > 0 else 0.0
    d = dv - b * dx
    return float(d @ d)


def profile_bins(x: np.ndarray) -> int:
    """Phase bins of a periodic profile: a quarter of the distinct targets (so each bin's
    level and slope rest on a few), between 4 and ``MAX_PROFILE_BINS``."""
    return int(np.clip(np.unique(np.round(x, 6)).size // 4, 4, MAX_PROFILE_BINS))


def init_periodic_shape(prep, W, terms, r_cur, term_cls, period_limits, periodic_scan):
    p_min, p_max = period_limits(prep)
    span = float(np.ptp(prep.x))
    if not (p_min > 0 and p_max > p_min and span > 0):
        return None
    ctx = prep.ctx()
    periodic = [t for t in terms if isinstance(t.effect, Periodic)]
    trend = np.column_stack([np.ones(prep.n), prep.x])
    if periodic:
        p0 = float(abs(periodic[0].effect.period))
        scan_trials = 1.0
    else:
        scan = periodic_scan(prep.x, r_cur, W, p_min, p_max, nuisance=trend)
        if scan is None:
            return None
        p0 = scan.best_period
        scan_trials = max(1.0, span * (1.0 / p_min - 1.0 / p_max))
    h_max = int(min(MAX_HARMONICS, np.floor(p0 / p_min)))
    if h_max < 2:
        return None
    proto = PeriodicShape(p0)
    keep, removed = _split(terms, proto, span)
    r = r_cur + _contribution(removed, ctx)

    def cols(period: float, h: int) -> np.ndarray:
        w = 2.0 * np.pi * prep.x / period
        return np.column_stack([f(k * w) for k in range(1, h + 1) for f in (np.sin, np.cos)])

    f0 = 1.0 / p0
    # repeated approaches of one target are averaged first: their scatter is noise, and in
    # phase order it would count as roughness at every period alike
    xs, inv = np.unique(np.round(prep.x, 6), return_inverse=True)
    means = np.bincount(inv, r) / np.bincount(inv)
    best_p, best_len = p0, np.inf
    for f in f0 + np.linspace(-1.0, 1.0, PERIOD_REFINE_POINTS) / span:
        if f <= 1.0 / p_max * 0.999 or f >= 1.0 / p_min:
            continue
        length = string_length(xs, means, 1.0 / f)
        if length < best_len:
            best_p, best_len = 1.0 / f, length
    h_max = int(min(MAX_HARMONICS, np.floor(best_p / p_min)))
    if h_max < 2:
        return None
    names = tuple(f"{c}{k}" for k in range(1, MAX_HARMONICS + 1) for c in ("a", "b"))
    variants = [(names[: 2 * h], cols(best_p, h)) for h in range(2, h_max + 1)]
    free, coef = _best_variant(W, r, variants, prep.n)
    e = PeriodicShape(best_p, **{k: float(v) for k, v in zip(free, coef)})
    df_ = PERIOD_FIT_RANGE / span
    bounds = {"period": (1.0 / (1.0 / best_p + df_), 1.0 / max(1.0 / best_p - df_, 1e-12))}
    k_removed = 2 * len(removed)        # amplitude and phase; the period is the same one
    return Proposal("periodic_shape", keep, removed, term_cls(e, ("period",) + free, bounds),
                    len(free) - k_removed, scan_trials * len(variants))
