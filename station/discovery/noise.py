"""Noise floor from repeated approaches, and the correlated-noise (AR(1)) model.

ISO 230-2 approaches every target several times from each direction.  The scatter
of those repeats is what the axis cannot do better than: the noise floor.  We take
a two-way additive fit (one mean per target-and-direction group, one per run) and
use its residual: the group means cancel every deterministic error of position and
direction, the run means cancel a slow drift between runs (drift is analysed as a
time signature, not counted as noise).

Laser readings of a settling axis are correlated from one point to the next (air
turbulence, servo hunting, the structure still moving).  An AR(1) process on the
within-run sequence is the simplest model of that; its coefficient ``phi`` sets the
effective sample size ``n (1 - phi) / (1 + phi)`` and the whitening transform
(Prais-Winsten) that all fits and tests use, so that information criteria, p-values
and standard errors are not fooled by correlated noise.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from station.discovery.data import Prepared

#: AR(1) coefficients are clipped to this range: beyond 0.95 the noise is a random
#: walk in practice and whitening would amplify rounding; below -0.5 is not a
#: physical settling process
PHI_MIN, PHI_MAX = -0.5, 0.95


@dataclass(frozen=True)
class NoiseFloor:
    sigma: float            # repeatability, deviation units (marginal standard deviation)
    phi: float              # AR(1) coefficient on the within-run sequence
    dof: int                # degrees of freedom behind sigma
    n_eff: float            # effective sample size of the whole recording
    method: str             # how sigma was obtained

    def to_dict(self) -> dict:
        return {"sigma": self.sigma, "ar1_phi": self.phi, "dof": self.dof,
                "n_effective": self.n_eff, "method": self.method}


def _two_way_residual(values: np.ndarray, group: np.ndarray, run: np.ndarray, iterations: int = 20) -> np.ndarray:
    """Residual of ``values ~ group + run`` (additive, unbalanced) by backfitting.

    Backfitting converges to the least-squares fit of the additive model; 20 sweeps
    is plenty for the nearly balanced designs of ISO 230-2.
    """
    _, run_idx = np.unique(run, return_inverse=True)
    ng, nr = int(group.max()) + 1, int(run_idx.max()) + 1
    cg = np.maximum(np.bincount(group, minlength=ng), 1)
    cr = np.maximum(np.bincount(run_idx, minlength=nr), 1)
    res = values.astype(float).copy()
    for _ in range(iterations):
        res -= (np.bincount(group, res, ng) / cg)[group]
        res -= (np.bincount(run_idx, res, nr) / cr)[run_idx]
    return res


def lag1_autocorrelation(values: np.ndarray, prev: np.ndarray) -> float:
    """Pooled lag-1 autocorrelation within runs (pairs of consecutive rows of one run)."""
    has = prev >= 0
    if np.count_nonzero(has) < 3:
        return 0.0
    a, b = values[has], values[prev[has]]
    den = np.sum(values ** 2)
    return float(np.sum(a * b) / den) if den > 0 else 0.0


def estimate_noise(prep: Prepared) -> NoiseFloor:
    """Noise floor and AR(1) coefficient of a prepared recording."""
    n = prep.n
    ng = int(prep.group.max()) + 1
    nruns = np.unique(prep.run).size
    counts = np.bincount(prep.group, minlength=ng)
    repeated = counts[prep.group] >= 2
    dof = int(np.count_nonzero(repeated)) - int(np.count_nonzero(counts >= 2)) - (nruns - 1)
    if dof >= 5:
        res = _two_way_residual(prep.residual, prep.group, prep.run)
        res = np.where(repeated, res, 0.0)
        sigma = float(np.sqrt(np.sum(res ** 2) / dof))
        method = "repeated approaches (two-way fit: target-direction group + run)"
        # successive pairs are only meaningful between repeated rows
        r_phi = lag1_autocorrelation(res, np.where(repeated[np.maximum(prep.prev, 0)] & (prep.prev >= 0), prep.prev, -1))
        per_run = max(n / nruns, 2.0)
    else:
        # no repeats: von Neumann's successive differences within runs, which
        # cancel any error that is smooth over one target step
        has = prep.prev >= 0
        d = prep.residual[has] - prep.residual[prep.prev[has]]
        sigma = float(np.sqrt(np.mean(d ** 2) / 2.0)) if d.size else float(np.std(prep.residual))
        dof = int(d.size)
        method = "successive differences within runs (no repeated approaches)"
        r_phi = 0.0
        per_run = max(n / nruns, 2.0)
    # bias of the lag-1 estimate after removing a mean from short series:
    # E[r1] ~ phi - (1 + 3 phi) / m (Marriott & Pope, Biometrika 1954)
    phi = (r_phi + 1.0 / per_run) / (1.0 - 3.0 / per_run) if per_run > 6 else r_phi
    phi = float(np.clip(phi, PHI_MIN, PHI_MAX))
    if sigma <= 0 or not np.isfinite(sigma):
        sigma = float(np.std(prep.residual)) or 1e-12
    n_eff = n * (1 - phi) / (1 + phi)
    return NoiseFloor(sigma=sigma, phi=phi, dof=dof, n_eff=float(n_eff), method=method)


class Whitener:
    """Prais-Winsten transform for AR(1) noise along each run.

    ``w[i] = v[i] - phi v[prev[i]]`` and ``w[first] = sqrt(1 - phi^2) v[first]``: after it,
    AR(1) noise is white with the innovation variance, so ordinary least squares,
    BIC and likelihood-ratio tests apply (generalised least squares).
    """

    def __init__(self, prev: np.ndarray, phi: float):
        self.prev = prev
        self.phi = float(phi)
        self.first = prev < 0
        self.scale_first = np.sqrt(1.0 - self.phi ** 2)
        idx = np.arange(prev.size)
        #: runs contiguous in file order (the usual case): the previous row is the row
        #: before, and the transform is a slice difference instead of a gather
        self.contiguous = bool(np.all(prev[~self.first] == idx[~self.first] - 1))

    def __call__(self, v: np.ndarray) -> np.ndarray:
        if self.phi == 0.0:
            return v
        p = np.maximum(self.prev, 0)
        w = v - self.phi * v[p]
        w[self.first] = self.scale_first * v[self.first]
        return w

    def along_last(self, v: np.ndarray) -> np.ndarray:
        """The same transform on rows-as-last-axis arrays, shape (..., N): many series at once."""
        if self.phi == 0.0:
            return v
        if self.contiguous:
            w = np.empty_like(v)
            np.subtract(v[..., 1:], self.phi * v[..., :-1], out=w[..., 1:])
            w[..., 0] = v[..., 0]
        else:
            w = v - self.phi * v[..., np.maximum(self.prev, 0)]
        w[..., self.first] = self.scale_first * v[..., self.first]
        return w
