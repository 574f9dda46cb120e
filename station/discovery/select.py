"""Forward selection of effects: BIC, a corrected likelihood-ratio test, significance,
physics and cross-validation by run must all agree before an effect is claimed.

Why so many gates?  A claimed effect goes into the twin and into compensation; a
false one makes the machine worse.  Each gate catches a different failure:

* BIC (Schwarz 1978) penalises parameters: ``delta_bic < 0`` is required;
* the likelihood-ratio test, with the scan behind nonlinear candidates counted
  (Bonferroni over the scanned hypotheses) and Bonferroni over the candidates
  tried at the step, keeps the family-wise false-claim rate at ``ALPHA`` per step;
* ``|value / se| >= MIN_Z`` refuses a fit that is real only through its shape;
* the physical check refuses, e.g., tau <= 0 or a period the targets cannot resolve;
* cross-validation by run (fit on all runs but one, predict the held-out run)
  refuses an effect that does not generalise to a run it has not seen.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy import stats

from station.effects import Eccentricity, Periodic, ThermalDrift, EvalContext
from station.discovery.data import Prepared
from station.discovery.fit import FitResult, Term, fit_terms
from station.discovery.library import Candidate, LocalDefect, candidates, local_defect_columns, local_defect_grid, \
    period_limits, separating_measurement
from station.discovery.noise import Whitener
from station.discovery.scans import best_column, periodic_scan

#: family-wise false-claim rate per selection step (the bench checks <= 5 % overall)
ALPHA = 0.01
#: |parameter / standard error| needed: 3 sigma, the metrologist's usual "significant"
MIN_Z = 3.0
#: BIC difference below which two candidates are "not told apart" (Kass & Raftery
#: 1995: a difference under 6 is at best "positive", not "strong", evidence)
AMBIGUOUS_DELTA_BIC = 6.0
#: at most this many effects are claimed (more would over-fit an ISO campaign)
MAX_EFFECTS = 5


@dataclass
class Trial:
    name: str
    fit: FitResult | None
    delta_bic: float
    p_value: float
    z: float
    reason: str | None = None     # why refused, None when it passed every gate

    def to_dict(self) -> dict:
        return {"name": self.name, "delta_bic": _finite(self.delta_bic), "p_value": _finite(self.p_value),
                "z": _finite(self.z), "refused_because": self.reason}


def _finite(v: float) -> float | None:
    return float(v) if np.isfinite(v) else None


@dataclass
class Selection:
    fit: FitResult
    steps: list[dict] = field(default_factory=list)           # one per accepted effect
    trials: list[list[Trial]] = field(default_factory=list)   # every candidate at every step
    ambiguities: list[dict] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)


def _init_terms(c: Candidate, prep: Prepared, W: Whitener, r_cur: np.ndarray) -> Term | None:
    """A starting point for candidate ``c`` from a scan of the current residual."""
    ctx = prep.ctx()
    ones = np.ones((prep.n, 1))
    trend = np.column_stack([ones, prep.x])
    if c.name == "periodic":
        p_min, p_max = period_limits(prep)
        scan = periodic_scan(prep.x, r_cur, W, p_min, p_max, nuisance=trend)
        if scan is None:
            return None
        e = Periodic(scan.best_period, scan.best_amplitude, scan.best_phase)
        return Term(e, c.free, c.bounds)
    if c.name == "local_defect":
        centres, widths = local_defect_grid(prep)
        cols = local_defect_columns(prep, centres, widths)
        k, coef, _ = best_column(r_cur, cols, W, np.column_stack([trend, prep.x ** 2]))
        return Term(LocalDefect(float(centres[k]), float(widths[k]), coef), c.free, c.bounds)
    inits = c.inits(prep)
    if c.name == "thermal_drift":
        cols = np.column_stack([e.evaluate(ctx) for e in inits])
        k, coef, _ = best_column(r_cur, cols, W, ones)
        return Term(inits[k].with_parameters(amplitude=coef), c.free, c.bounds)
    if c.name == "eccentricity":
        cols = np.column_stack([e.evaluate(ctx) for e in inits])
        coef, *_ = np.linalg.lstsq(W(cols), W(r_cur), rcond=None)
        a, b = coef  # a sin(x) + b cos(x) = A sin(x + phase)
        return Term(Eccentricity(float(np.hypot(a, b)), float(np.arctan2(b, a))), c.free, c.bounds)
    return Term(inits[0], c.free, c.bounds)


def cv_score(prep: Prepared, W: Whitener, terms: list[Term]) -> float | None:
    """Sum over runs of the whitened squared error predicting each run from the others."""
    runs = np.unique(prep.run)
    if runs.size < 3:
        return None
    total = 0.0
    for run in runs:
        train = prep.run != run
        f = fit_terms(prep, W, terms, mask=train, max_nfev=100)
        held = prep.subset(~train)
        pred = np.zeros(held.n)
        ctx = held.ctx()
        for t in f.terms:
            pred = pred + t.effect.evaluate(ctx)
        w = Whitener(held.prev, W.phi)(held.residual - pred)
        total += float(w @ w)
    return total


def _z_of(fit: FitResult, i: int, magnitude: str) -> float:
    se = fit.stderr[i].get(magnitude, np.inf)
    v = abs(float(getattr(fit.terms[i].effect, magnitude)))
    return v / se if se > 0 else np.inf


def _backward_eliminate(prep: Prepared, W: Whitener, fit: FitResult, pool: list[Candidate]):
    """Drop effects that later additions made redundant, weakest first.

    An offset accepted early may be absorbed by a drift accepted later, for
    example; keeping it would claim an effect the final model does not need.  An
    effect stays when its magnitude is still ``MIN_Z`` standard errors from zero
    *or* removing it fails the (scan-corrected) likelihood-ratio test at ``ALPHA``;
    the second rule keeps a drift whose amplitude and tau are correlated (each
    uncertain) although together they are clearly needed.
    """
    by_name = {c.name: c for c in pool}
    dropped: list[str] = []
    n = prep.n
    while len(fit.terms) > 1:
        weakest, weakest_p, weakest_fit = None, -1.0, None
        for i, t in enumerate(fit.terms):
            c = by_name.get(t.effect.name)
            magnitude = c.magnitude if c else t.free[0]
            if _z_of(fit, i, magnitude) >= MIN_Z:
                continue
            reduced = fit_terms(prep, W, [u for j, u in enumerate(fit.terms) if j != i])
            lr = n * np.log(max(reduced.rss_w, 1e-300) / max(fit.rss_w, 1e-300))
            trials, df = (c.trials, c.df_single) if c else (1.0, len(t.free))
            p = float(min(1.0, trials * stats.chi2.sf(max(lr, 0.0), df)))
            if p >= ALPHA and p > weakest_p:
                weakest, weakest_p, weakest_fit = i, p, reduced
        if weakest is None:
            break
        dropped.append(fit.terms[weakest].effect.name)
        fit = weakest_fit
    return fit, dropped


def forward_select(prep: Prepared, W: Whitener, exclude: set[str] = frozenset()) -> Selection:
    """Add effects one at a time while one passes every gate (module docstring)."""
    pool = candidates(prep, exclude)
    current = fit_terms(prep, W, [])
    sel = Selection(fit=current)
    cv_current = cv_score(prep, W, [])
    if cv_current is None:
        sel.notes.append("fewer than 3 runs: cross-validation by run was not possible")
    n = prep.n
    while pool and len(current.terms) < MAX_EFFECTS:
        trials: list[Trial] = []
        m = len(pool)
        for c in pool:
            term = _init_terms(c, prep, W, current.residual)
            if term is None:
                trials.append(Trial(c.name, None, np.inf, 1.0, 0.0, "no starting point"))
                continue
            f = fit_terms(prep, W, list(current.terms) + [term])
            d_bic = f.bic() - current.bic()
            lr = n * np.log(max(current.rss_w, 1e-300) / max(f.rss_w, 1e-300))
            p = float(min(1.0, c.trials * stats.chi2.sf(max(lr, 0.0), c.df_single)))
            new = f.terms[-1].effect
            se = f.stderr[-1].get(c.magnitude, np.inf)
            z = abs(float(getattr(new, c.magnitude))) / se if se > 0 else np.inf
            trials.append(Trial(c.name, f, d_bic, p, z))
        trials.sort(key=lambda t: t.delta_bic)
        accepted: Trial | None = None
        for t in trials:
            if t.reason:
                continue
            c = next(c for c in pool if c.name == t.name)
            if not t.delta_bic < 0:
                t.reason = f"BIC does not improve (delta {t.delta_bic:+.1f})"
            elif not t.p_value < ALPHA / m:
                t.reason = f"likelihood-ratio p = {t.p_value:.3g} not below {ALPHA}/{m} (Bonferroni)"
            elif not t.z >= MIN_Z:
                t.reason = f"parameter '{c.magnitude}' only {t.z:.1f} standard errors from zero"
            elif (why := c.physical(t.fit.terms[-1].effect, prep)) is not None:
                t.reason = "not physical: " + why
            if t.reason or accepted is not None:
                continue
            cv_new = cv_score(prep, W, t.fit.terms) if cv_current is not None else None
            if cv_new is not None and not cv_new < cv_current:
                t.reason = (f"does not predict held-out runs better (cross-validated SSE "
                            f"{cv_new:.4g} vs {cv_current:.4g})")
                continue
            accepted = t
            if cv_new is not None:
                cv_current = cv_new
        sel.trials.append(trials)
        if accepted is None:
            break
        for t in trials:
            if t is not accepted and t.reason is None and t.delta_bic - accepted.delta_bic < AMBIGUOUS_DELTA_BIC:
                sel.ambiguities.append({
                    "effects": [accepted.name, t.name],
                    "delta_bic": [float(accepted.delta_bic), float(t.delta_bic)],
                    "description": f"{accepted.name} and {t.name} explain the residual almost equally well "
                                   f"(BIC differs by {t.delta_bic - accepted.delta_bic:.1f}); {accepted.name} was kept",
                    "separate_by": separating_measurement(accepted.name, t.name),
                })
        sel.steps.append({"name": accepted.name, "delta_bic": float(accepted.delta_bic),
                          "p_value": float(accepted.p_value), "z": float(accepted.z)})
        current = accepted.fit
        pool = [c for c in pool if c.name != accepted.name]
        current, dropped = _backward_eliminate(prep, W, current, candidates(prep, exclude) )
        for name in dropped:
            sel.notes.append(f"{name} was dropped after later effects made it insignificant")
            sel.steps = [s for s in sel.steps if s["name"] != name]
    sel.fit = current
    return sel
