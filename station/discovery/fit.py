"""Joint nonlinear least-squares fit of effects to the residual (generalised LS).

The model of the residual is the sum of the chosen effects, each evaluated by its
own class in :mod:`station.effects`.  The fit minimises the whitened misfit
``W (r - sum effects)`` with :func:`scipy.optimize.least_squares`; standard errors
come from the Jacobian at the optimum, ``cov = s^2 (J^T J)^-1`` with ``s^2`` the
whitened residual variance.  Because the Jacobian is of the *whitened* problem the
errors already allow for the AR(1) noise; if the whitened residual is still
correlated (lag-1 autocorrelation rho > 0), they are inflated further by
``sqrt((1 + rho) / (1 - rho))``, the variance-inflation factor of an AR(1) mean.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import least_squares

from station.effects import Effect, EvalContext
from station.discovery.data import Prepared
from station.discovery.noise import Whitener, lag1_autocorrelation


@dataclass
class Term:
    """An effect in the fit: its current value, which parameters are free, their bounds.

    ``scanned`` names parameters set by a scan rather than by least squares (a step's
    position: the misfit is flat within a gap between targets and jumps between gaps,
    so it has no derivative); they are held here but count as parameters (BIC, the
    residual's degrees of freedom), since the data chose them.
    """

    effect: Effect
    free: tuple[str, ...]
    bounds: dict[str, tuple[float, float]] = field(default_factory=dict)
    scanned: tuple[str, ...] = ()


@dataclass
class FitResult:
    terms: list[Term]
    stderr: list[dict[str, float]]
    rss_w: float            # whitened residual sum of squares
    n: int
    k: int                  # number of free parameters
    residual: np.ndarray    # raw (unwhitened) residual after the fit
    inflation: float = 1.0

    @property
    def effects(self) -> list[Effect]:
        return [t.effect for t in self.terms]

    def bic(self) -> float:
        return bic(self.rss_w, self.n, self.k)


def bic(rss_w: float, n: int, k: int) -> float:
    """Schwarz's BIC of a Gaussian model with unknown variance: n ln(RSS/n) + k ln n."""
    return float(n * np.log(max(rss_w, 1e-300) / n) + k * np.log(n))


def total(effects, ctx: EvalContext) -> np.ndarray:
    out = np.zeros_like(ctx.x)
    for e in effects:
        out = out + e.evaluate(ctx)
    return out


def normalise(e: Effect) -> Effect:
    """One canonical form for sign-symmetric parameters: amplitude >= 0, phase in (-pi, pi]."""
    names = e.parameter_names
    if "phase" in names and "amplitude" in names:
        a, ph = float(e.amplitude), float(e.phase)
        if a < 0:
            a, ph = -a, ph + np.pi
        ph = float(np.angle(np.exp(1j * ph)))
        e = e.with_parameters(amplitude=a, phase=ph)
    if "width" in names:
        e = e.with_parameters(width=abs(float(e.width)))
    return e


def fit_terms(prep: Prepared, W: Whitener, terms: list[Term], mask: np.ndarray | None = None,
              max_nfev: int = 200) -> FitResult:
    """Fit all free parameters of ``terms`` jointly to ``prep.residual`` (rows in ``mask``)."""
    if mask is not None:
        prep = prep.subset(mask)
        W = Whitener(prep.prev, W.phi)
    ctx = prep.ctx()
    r = prep.residual
    slots = [(i, name) for i, t in enumerate(terms) for name in t.free]
    k_scanned = sum(len(t.scanned) for t in terms)
    if not slots:
        res = r - total([t.effect for t in terms], ctx)
        rw = W(res)
        return FitResult(list(terms), [{} for _ in terms], float(rw @ rw), r.size, k_scanned, res)
    x0 = np.array([float(getattr(terms[i].effect, n)) for i, n in slots])
    lo = np.array([terms[i].bounds.get(n, (-np.inf, np.inf))[0] for i, n in slots])
    hi = np.array([terms[i].bounds.get(n, (-np.inf, np.inf))[1] for i, n in slots])
    span = np.where(np.isfinite(hi - lo), hi - lo, 1.0)
    x0 = np.clip(x0, lo + 1e-9 * span, hi - 1e-9 * span)

    def build(p: np.ndarray) -> list[Effect]:
        vals: list[dict[str, float]] = [{} for _ in terms]
        for (i, n), v in zip(slots, p):
            vals[i][n] = float(v)
        return [t.effect.with_parameters(**v) if v else t.effect for t, v in zip(terms, vals)]

    def fun(p: np.ndarray) -> np.ndarray:
        return W(r - total(build(p), ctx))

    sol = least_squares(fun, x0, bounds=(lo, hi), x_scale="jac", method="trf", max_nfev=max_nfev)
    effects = build(sol.x)
    res = r - total(effects, ctx)
    rw = W(res)
    rss = float(rw @ rw)
    n, k = r.size, len(slots) + k_scanned
    s2 = rss / max(n - k, 1)
    J = sol.jac
    cov = s2 * np.linalg.pinv(J.T @ J)
    rho = lag1_autocorrelation(rw, prep.prev)
    infl = float(np.sqrt((1 + rho) / (1 - rho))) if 0 < rho < 0.95 else 1.0
    se = np.sqrt(np.clip(np.diag(cov), 0, None)) * infl
    stderr: list[dict[str, float]] = [{} for _ in terms]
    for (i, name), s in zip(slots, se):
        stderr[i][name] = float(s)
    new_terms = [dataclasses.replace(t, effect=normalise(e)) for t, e in zip(terms, effects)]
    return FitResult(new_terms, stderr, rss, n, k, res, infl)
