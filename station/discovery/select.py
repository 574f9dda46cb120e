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

None of these asks whether the effect *is* the structure it absorbs: structure
outside the vocabulary (a step in the scale, a bend, a sawtooth, a reversal that
grows along the travel) is real and repeats from run to run, so a vocabulary effect
that absorbs part of it passes them all.  Hence the *explains* gate (issue 20):
beside the vocabulary, the selection is offered descriptors
(:mod:`station.discovery.descriptors`), each a flexible generalisation of a family
of vocabulary effects, under the same gates.  An effect is claimed only if it
out-explains its own generalisation; when a descriptor wins, the effects it
contains are taken out and barred, every other effect must stay significant beside
it (backward elimination, and at the end against the descriptor's saturated form:
:func:`check_beside_descriptors`), and the descriptor is reported as a finding,
never as an effect.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

import numpy as np
from scipy import stats

from station.effects import Eccentricity, Periodic, Step, ThermalDrift, EvalContext
from station.discovery.data import Prepared
from station.discovery.descriptors import (
    Proposal, init_curvature, init_hysteresis, init_periodic_shape, is_descriptor,
)
from station.discovery.fit import FitResult, Term, fit_terms
from station.discovery.library import Candidate, LocalDefect, candidates, local_defect_columns, local_defect_grid, \
    period_limits, separating_measurement, step_columns, step_gaps, step_grid
from station.discovery.noise import Whitener
from station.discovery.scans import best_column, linear_test, periodic_scan, project_out, whitened_grid

#: family-wise false-claim rate per selection step (the bench checks <= 5 % overall)
ALPHA = 0.01
#: level of the descriptors' tests (structure outside the vocabulary): not a claim, so
#: no Bonferroni over the candidates; see the module docstring and forward_select
ALPHA_DESCRIPTOR = 0.05
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
    #: descriptors: (delta BIC, p-value, names) against the vocabulary effects it contains
    beyond: tuple[float, float, str] | None = None

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
    #: accepted descriptors (structure outside the vocabulary), like ``steps``
    descriptors: list[dict] = field(default_factory=list)

    @property
    def effect_indices(self) -> list[int]:
        """Indices into ``fit.terms`` of the vocabulary effects (claimable)."""
        return [i for i, t in enumerate(self.fit.terms) if not is_descriptor(t.effect)]

    @property
    def descriptor_indices(self) -> list[int]:
        return [i for i, t in enumerate(self.fit.terms) if is_descriptor(t.effect)]


#: descriptor name -> how it is tried (station.discovery.descriptors)
DESCRIPTOR_INITS = {
    "curvature": init_curvature,
    "hysteresis": init_hysteresis,
    "periodic_shape": lambda prep, W, terms, r, cls: init_periodic_shape(prep, W, terms, r, cls, period_limits,
                                                                         periodic_scan),
}


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
    if c.name == "step":
        positions = step_grid(prep)
        if positions.size == 0:
            return None
        cols = whitened_grid(("step", hash(prep.x.tobytes())), lambda: step_columns(prep, positions), W, trend)
        k, coef, _ = best_column(r_cur, cols, W, trend, projected=True)
        return Term(Step(float(positions[k]), coef), c.free, c.bounds, scanned=("position",))
    if c.name == "local_defect":
        centres, widths = local_defect_grid(prep)
        nuisance = np.column_stack([trend, prep.x ** 2])
        cols = whitened_grid(("local_defect", hash(prep.x.tobytes())),
                             lambda: local_defect_columns(prep, centres, widths), W, nuisance)
        k, coef, _ = best_column(r_cur, cols, W, nuisance, projected=True)
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
            if is_descriptor(t.effect):
                continue   # structure outside the vocabulary stays described (module docstring)
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


def _contained_alternative(prep: Prepared, W: Whitener, base: list[Term], residual: np.ndarray,
                           descriptor, offered: list[Candidate], base_fit: FitResult | None = None,
                           known: dict[str, FitResult] | None = None) -> FitResult:
    """``base`` plus the vocabulary effects the descriptor contains (those that may be
    offered), fitted: what the vocabulary itself does with that family.  ``base_fit``,
    when given, is the fit of ``base`` alone (returned when nothing is added);
    ``known`` the fits of ``base`` plus one candidate, by name, already made."""
    have = {t.effect.name for t in base}
    missing = [c for c in offered if c.name in descriptor.contains and c.name not in have]
    if not missing and base_fit is not None:
        return base_fit
    if len(missing) == 1 and known and missing[0].name in known:
        return known[missing[0].name]
    extra = [term for c in missing if (term := _init_terms(c, prep, W, residual)) is not None]
    return fit_terms(prep, W, list(base) + extra)


def _described_by(e, fit: FitResult, prep: Prepared) -> str | None:
    """The descriptor already in the model that contains effect ``e``, if any (e.g. a
    sine at a harmonic of a non-sinusoidal periodic error)."""
    span = float(np.ptp(prep.x))
    for t in fit.terms:
        if is_descriptor(t.effect) and t.effect.subsumes(e, span):
            return t.effect.name
    return None


def _lr_p(n: int, rss0: float, rss1: float, trials: float, df: int) -> float:
    lr = n * np.log(max(rss0, 1e-300) / max(rss1, 1e-300))
    return float(min(1.0, trials * stats.chi2.sf(max(lr, 0.0), max(df, 1))))


def _barred(fit: FitResult) -> set[str]:
    """Vocabulary effects the descriptors in the model contain: not offered beside them."""
    out: set[str] = set()
    for t in fit.terms:
        if is_descriptor(t.effect):
            out |= set(t.effect.barred())
    return out


def _recheck_descriptors(prep: Prepared, W: Whitener, fit: FitResult, sel: Selection,
                         offered: list[Candidate]) -> FitResult:
    """A descriptor stays only while it out-explains the effects it contains.

    Accepted early, a descriptor may have been taking up structure that a later
    effect explains (a curvature's quadratic term some of a periodic error not yet
    fitted); then it is replaced by those effects, fitted, if that is no worse by BIC
    or its advantage is no longer significant at ``ALPHA_DESCRIPTOR``.
    """
    n = prep.n
    for entry in list(sel.descriptors):
        i = next((i for i, t in enumerate(fit.terms) if t.effect.name == entry["name"]), None)
        if i is None:
            continue
        d = fit.terms[i].effect
        base = [t for j, t in enumerate(fit.terms) if j != i]
        ctx = prep.ctx()
        alt = _contained_alternative(prep, W, base, fit.residual + d.evaluate(ctx), d, offered)
        d_bic = fit.bic() - alt.bic()
        p = _lr_p(n, alt.rss_w, fit.rss_w, entry["trials"], max(fit.k - alt.k, 1))
        if d_bic < 0 and p < ALPHA_DESCRIPTOR:
            continue
        sel.descriptors.remove(entry)
        added = [t.effect.name for t in alt.terms[len(base):]]
        sel.notes.append(f"{d.name} was replaced by {' + '.join(added) or 'nothing'}: with the effects found "
                         f"since, it no longer explains more than they do (BIC {d_bic:+.1f}, p = {p:.2g})")
        for k, name in enumerate(added):
            without = fit_terms(prep, W, [t for j, t in enumerate(alt.terms) if j != len(base) + k])
            sel.steps.append({"name": name, "delta_bic": float(alt.bic() - without.bic()),
                              "p_value": _lr_p(n, without.rss_w, alt.rss_w, 1.0, len(alt.terms[len(base) + k].free)),
                              "z": float(_z_of(alt, len(base) + k, next(
                                  (c.magnitude for c in offered if c.name == name), alt.terms[len(base) + k].free[0])))})
        fit = alt
    return fit


def forward_select(prep: Prepared, W: Whitener, exclude: set[str] = frozenset()) -> Selection:
    """Add effects (and descriptors) one at a time while one passes every gate (module docstring)."""
    every = candidates(prep, exclude)
    used: set[str] = set()        # offered once and accepted: not offered again (even when dropped)
    current = fit_terms(prep, W, [])
    sel = Selection(fit=current)
    cv_current = cv_score(prep, W, [])
    if cv_current is None:
        sel.notes.append("fewer than 3 runs: cross-validation by run was not possible")
    n = prep.n
    while len(current.terms) < MAX_EFFECTS:
        barred = _barred(current)
        pool = [c for c in every if c.name not in used and c.name not in barred]
        descriptors = [d for d in DESCRIPTOR_INITS if d not in used and d not in exclude]
        if not pool and not descriptors:
            break
        trials: list[Trial] = []
        proposals: dict[int, Proposal] = {}
        # Bonferroni over the claims that may be made at this step: the vocabulary's
        # candidates (descriptors are not claims; they have their own level, below)
        m = max(len(pool), 1)
        for c in pool:
            term = _init_terms(c, prep, W, current.residual)
            if term is None:
                trials.append(Trial(c.name, None, np.inf, 1.0, 0.0, "no starting point"))
                continue
            f = fit_terms(prep, W, list(current.terms) + [term])
            d_bic = f.bic() - current.bic()
            p = _lr_p(n, current.rss_w, f.rss_w, c.trials, c.df_single)
            new = f.terms[-1].effect
            se = f.stderr[-1].get(c.magnitude, np.inf)
            z = abs(float(getattr(new, c.magnitude))) / se if se > 0 else np.inf
            trials.append(Trial(c.name, f, d_bic, p, z))
        for name in descriptors:
            prop = DESCRIPTOR_INITS[name](prep, W, list(current.terms), current.residual, Term)
            if prop is None:
                trials.append(Trial(name, None, np.inf, 1.0, 0.0, "no starting point"))
                continue
            f = fit_terms(prep, W, prop.keep + [prop.term])
            d_bic = f.bic() - current.bic()
            p = _lr_p(n, current.rss_w, f.rss_w, prop.trials, prop.df)
            t = Trial(name, f, d_bic, p, np.inf)
            # what it explains beyond the vocabulary effects it contains, fitted as well as
            # they can be: a descriptor must out-explain them, not merely bundle them
            alt = _contained_alternative(prep, W, list(current.terms), current.residual, prop.term.effect, pool,
                                         current, {t.name: t.fit for t in trials if t.fit is not None})
            t.beyond = (f.bic() - alt.bic(), _lr_p(n, alt.rss_w, f.rss_w, prop.trials, max(f.k - alt.k, 1)),
                        " + ".join(sorted(prop.term.effect.contains)))
            proposals[id(t)] = prop
            trials.append(t)
        trials.sort(key=lambda t: t.delta_bic)
        accepted: Trial | None = None
        for t in trials:
            if t.reason:
                continue
            c = next((c for c in pool if c.name == t.name), None)
            # a descriptor is not a claim: it decides between claiming vocabulary effects and
            # describing the structure as a finding, so it is tested at ALPHA_DESCRIPTOR without the
            # Bonferroni over the candidates (erring towards it costs a claim, not a false one)
            level, level_text = ((ALPHA_DESCRIPTOR, f"{ALPHA_DESCRIPTOR}") if t.beyond is not None
                                 else (ALPHA / m, f"{ALPHA}/{m} (Bonferroni)"))
            if not t.delta_bic < 0:
                t.reason = f"BIC does not improve (delta {t.delta_bic:+.1f})"
            elif not t.p_value < level:
                t.reason = f"likelihood-ratio p = {t.p_value:.3g} not below {level_text}"
            elif c is not None and not t.z >= MIN_Z:
                t.reason = f"parameter '{c.magnitude}' only {t.z:.1f} standard errors from zero"
            elif c is not None and (why := c.physical(t.fit.terms[-1].effect, prep)) is not None:
                t.reason = "not physical: " + why
            elif c is not None and (host := _described_by(t.fit.terms[-1].effect, current, prep)) is not None:
                t.reason = (f"part of the {host} found (structure outside the vocabulary): "
                            f"claimed alone, it would describe that structure wrongly")
            elif t.beyond is not None and not t.beyond[0] < 0:
                t.reason = f"explains no more than {t.beyond[2]} would (BIC {t.beyond[0]:+.1f})"
            elif t.beyond is not None and not t.beyond[1] < level:
                t.reason = (f"what it explains beyond {t.beyond[2]} is not significant "
                            f"(p = {t.beyond[1]:.3g}, not below {level_text})")
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
        prop = proposals.get(id(accepted))
        for t in trials:
            if (t is not accepted and t.reason is None and t.delta_bic - accepted.delta_bic < AMBIGUOUS_DELTA_BIC
                    and prop is None and id(t) not in proposals):
                sel.ambiguities.append({
                    "effects": [accepted.name, t.name],
                    "delta_bic": [float(accepted.delta_bic), float(t.delta_bic)],
                    "description": f"{accepted.name} and {t.name} explain the residual almost equally well "
                                   f"(BIC differs by {t.delta_bic - accepted.delta_bic:.1f}); {accepted.name} was kept",
                    "separate_by": separating_measurement(accepted.name, t.name),
                })
        used.add(accepted.name)
        current = accepted.fit
        if prop is not None:
            sel.descriptors.append({"name": accepted.name, "delta_bic": float(accepted.delta_bic),
                                    "p_value": float(accepted.p_value), "trials": float(prop.trials)})
            desc = current.terms[-1].effect
            # the vocabulary effects it contains cannot be told from its own parts: out, and
            # not offered while it is in the model (_barred)
            for u in prop.removed:
                sel.notes.append(f"{u.effect.name} was taken out: the {desc.name} found contains it, and "
                                 f"{u.effect.name} alone does not describe what the recording shows")
            gone = {u.effect.name for u in prop.removed}
            sel.steps = [s_ for s_ in sel.steps if s_["name"] not in gone]
        else:
            sel.steps.append({"name": accepted.name, "delta_bic": float(accepted.delta_bic),
                              "p_value": float(accepted.p_value), "z": float(accepted.z)})
        current, dropped = _backward_eliminate(prep, W, current, every)
        for name in dropped:
            sel.notes.append(f"{name} was dropped after later effects made it insignificant")
            sel.steps = [s for s in sel.steps if s["name"] != name]
        if sel.descriptors:
            k = len(sel.descriptors)
            current = _recheck_descriptors(prep, W, current, sel, [c for c in every if c.name in _barred(current)
                                                                    or c.name not in used])
            if len(sel.descriptors) < k:
                current, dropped = _backward_eliminate(prep, W, current, every)
                for name in dropped:
                    sel.notes.append(f"{name} was dropped after later effects made it insignificant")
                    sel.steps = [s for s in sel.steps if s["name"] != name]
    current = refine_steps(prep, W, current)
    current, taken = check_beside_descriptors(prep, W, current, every,
                                              {d["name"]: d["trials"] for d in sel.descriptors})
    for name, why in taken:
        sel.notes.append(f"{name} was taken out: {why}")
        sel.steps = [s for s in sel.steps if s["name"] != name]
        sel.descriptors = [d for d in sel.descriptors if d["name"] != name]
    sel.fit = current
    return sel


def check_beside_descriptors(prep: Prepared, W: Whitener, fit: FitResult, pool: list[Candidate],
                             descriptor_trials: dict[str, float] | None = None):
    """Every effect beside a descriptor must still be significant against the most
    flexible description of the descriptor's family the recording supports.

    A descriptor is parsimonious (a few harmonics, a low-degree polynomial) so that
    it can win the selection; what it leaves of the structure it describes is still
    there, concentrated where the structure is sharp (a sawtooth's jump, in every
    period), and an effect nearly collinear with the family (thermal expansion at an
    almost constant temperature beside a curvature, which contains the scale error)
    may take up part of it.  So each effect's magnitude column is tested again,
    linearised at the fit, with the other terms' free parameters and every other
    descriptor's *saturated* columns (a mean per phase bin of a periodic error, the
    full polynomial of a curvature, the full varying reversal) as nuisance; the
    p-value is corrected for the scan behind the effect as in the selection, at
    ``ALPHA`` over the vocabulary's candidates (Bonferroni, as when it was first
    accepted).  A descriptor beside another is tested the same way on all its
    columns, at ``ALPHA_DESCRIPTOR``.  What fails is part of the described structure
    and is taken out; the check repeats until nothing fails.
    """
    taken: list[tuple[str, str]] = []
    by_name = {c.name: c for c in pool}
    ctx = prep.ctx()
    while True:
        sat_all = [(j, t.effect, t.effect.saturated_columns(prep)) for j, t in enumerate(fit.terms)
                   if is_descriptor(t.effect)]
        sat_all = [(j, d, cols) for j, d, cols in sat_all if cols is not None]
        if not sat_all:
            return fit, taken
        out = None
        for i, t in enumerate(fit.terms):
            sat = [(j, d, cols) for j, d, cols in sat_all if j != i]
            if not sat or not t.free:
                continue
            if is_descriptor(t.effect):
                test_names = t.free
                trials = (descriptor_trials or {}).get(t.effect.name, 1.0)
                level = ALPHA_DESCRIPTOR
            else:
                level = ALPHA / max(len(pool), 1)
                c = by_name.get(t.effect.name)
                magnitude = c.magnitude if c else t.free[0]
                if magnitude not in t.free:
                    continue
                test_names = (magnitude,)
                trials = c.trials if c else 1.0
            r = fit.residual + t.effect.evaluate(ctx) + sum(d.evaluate(ctx) for _, d, _ in sat)
            nuis = [cols for _, _, cols in sat]
            sat_idx = {j for j, _, _ in sat}
            for j, u in enumerate(fit.terms):
                if j != i and u.free and j not in sat_idx:
                    nuis.append(u.effect.jacobian(ctx, u.free))
            p, _, _ = linear_test(W, r, np.column_stack(nuis), t.effect.jacobian(ctx, test_names))
            if min(1.0, trials * p) >= level:
                names = ", ".join(d.name for _, d, _ in sat)
                out = (i, t.effect.name,
                       f"beside the {names} found it is not significant against a free description of "
                       f"that structure (p = {min(1.0, trials * p):.2g}): it was taking up part of it")
                break
        if out is None:
            return fit, taken
        i, name, why = out
        taken.append((name, why))
        fit = fit_terms(prep, W, [u for j, u in enumerate(fit.terms) if j != i])


def _jacobian_columns(prep: Prepared, terms: list[Term], skip: int) -> np.ndarray:
    """d(prediction)/d(free parameter) of every term but ``skip``, at the fitted values."""
    ctx = prep.ctx()
    cols = [t.effect.jacobian(ctx, t.free) for j, t in enumerate(terms) if j != skip and t.free]
    return np.column_stack(cols) if cols else np.zeros((prep.n, 0))


#: chi-square(1) 95 % point: gaps whose profile misfit is within this (in units of the
#: residual variance) of the best gap are not excluded by the data
PROFILE_CHI2_95 = 3.841
#: columns of the step profile evaluated at once (memory bound on dense recordings)
_PROFILE_CHUNK = 256


def refine_steps(prep: Prepared, W: Whitener, fit: FitResult) -> FitResult:
    """Place every step in its best gap and give its position an honest uncertainty.

    The misfit of a step is flat within a gap between targets and jumps between
    gaps, so its position has no derivative and no Jacobian standard error.  Its
    profile is scanned instead: for every gap, the misfit with the step there and
    the other terms' free parameters re-fitted (linearised about the fit).  The
    step goes to the middle of the best gap; the gaps whose misfit is within the
    chi-square(1) 95 % point of the best are the positions the data allow, and the
    reported ``stderr['position']`` is the larger distance from the position to the
    ends of those gaps divided by 1.96: +-1.96 standard errors covers every joint
    position the recording cannot exclude (a conservative, not a Gaussian, error).
    """
    idx = [i for i, t in enumerate(fit.terms) if isinstance(t.effect, Step)]
    if not idx:
        return fit
    left, right = step_gaps(prep)
    if left.size == 0:
        return fit
    mids = (left + right) / 2.0
    ctx = prep.ctx()
    for i in idx:
        step = fit.terms[i].effect
        r = fit.residual + step.evaluate(ctx)
        J = _jacobian_columns(prep, fit.terms, i)
        red = np.empty(mids.size)
        rw = project_out(W, J if J.shape[1] else None, r)[0]
        for a in range(0, mids.size, _PROFILE_CHUNK):
            cols = step_columns(prep, mids[a:a + _PROFILE_CHUNK])
            cw = project_out(W, J if J.shape[1] else None, cols)[0]
            cc = np.sum(cw * cw, 0)
            red[a:a + _PROFILE_CHUNK] = np.where(cc > 1e-12, (cw.T @ rw) ** 2 / np.where(cc > 1e-12, cc, 1.0), 0.0)
        k = int(np.argmax(red))
        s2 = max(float(rw @ rw) - red[k], 1e-300) / max(prep.n - fit.k, 1)
        ok = red[k] - red <= PROFILE_CHI2_95 * s2
        lo, hi = float(left[ok].min()), float(right[ok].max())
        pos = float(mids[k])
        if pos != step.position:
            terms = list(fit.terms)
            terms[i] = dataclasses.replace(terms[i], effect=step.with_parameters(position=pos))
            fit = fit_terms(prep, W, terms)
        fit.stderr[i]["position"] = max(pos - lo, hi - pos) / 1.96
    return fit
