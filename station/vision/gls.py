"""Generalised least squares for the photometric fit: the wall's grain as correlated noise.

Why: the photometric fit (``photometric.refine_hole``) weighs each pixel by its own
variance (weighted least squares).  The wall's fine grain is not white: it is blurred
by its own texture scale and by the camera, so its power sits at the low spatial
frequencies where the blurred rim's signal sits too, and it lives on the wall only (the
hole cuts it before the camera blurs it).  Against the Cramer-Rao bound of
``station bench vision-bound`` (whose noise is exactly this) a weighted fit loses 10-45 %
of sigma where the grain is strong (docs/vision-history.md, round 14); one Gauss-Newton
step with the noise's covariance C, from the weighted fit's solution, takes it back.

Noise model on the fit's pixels (x: a pixel's value about the model):

    C = diag(v_sensor) + g B_s D K K^T D B_s^T g

v_sensor: the sensor's variance (shot + read noise), the hole's inside residuals give it
there, the wall's from the split below; K: the grain's own kernel, a Gaussian of
``corr_px``; D: the wall's share of each pixel (1 inside the wall, 0 inside the hole, the
pixel's area across the rim); B_s: the camera's blur; g: the grain's amplitude.  The wall
ring's residuals (``photometric``: its grooves and a smooth level removed), their
variance and their correlation at lags 1-3 px, split the wall's variance into sensor and
grain and give the grain's correlation length: nothing of the renderer is assumed but
the Gaussian shape of the correlation.  What the ring keeps of grooves and blotches
counts as grain, so C's scale comes out large; the fit scales its uncertainties by the
whitened residuals' chi-square, which C's scale does not bias.

C^-1 applied to the Jacobian's columns and the residual by conjugate gradients
(Jacobi preconditioner, to 1e-3: a Gauss-Newton step needs no more), as the bound does:
C is never formed.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np


#: an 8-bit pixel's quantisation variance (DN^2): the least noise any pixel has (the
#: bound's sensor noise carries it too: ``station.bench.vision_bound``)
QUANT_VAR_DN2 = 1.0 / 12.0


@dataclass(frozen=True)
class GrainNoise:
    """The noise of one hole's pixels (DN^2 and px)."""

    sensor_in_var: float  # the sensor's variance on the hole's side
    sensor_out_var: float  # ... on the wall's side
    grain_var: float  # the grain's per-pixel variance on the open wall, after the camera
    corr_px: float  # the grain's own correlation scale (Gaussian sigma of its kernel)


def _lag_corr(grid: np.ndarray, ok: np.ndarray, lag: int) -> float:
    """The correlation of ``grid`` at ``lag`` px along x and y, over pixel pairs both ``ok``."""
    num = den = 0.0
    for a, b, oa, ob in ((grid[:, :-lag], grid[:, lag:], ok[:, :-lag], ok[:, lag:]),
                         (grid[:-lag, :], grid[lag:, :], ok[:-lag, :], ok[lag:, :])):
        both = oa & ob
        num += float(np.sum(a[both] * b[both]))
        den += float(np.sum(0.5 * (a[both] ** 2 + b[both] ** 2)))
    return num / den if den > 0 else 0.0


def estimate_noise(res_grid: np.ndarray, wall_ok: np.ndarray, inner_var: float, s_cam: float) -> GrainNoise | None:
    """The hole's ``GrainNoise`` from the weighted fit's residuals on the ROI grid:
    ``wall_ok`` marks the open wall's pixels (beyond the rim's blur), ``inner_var`` the
    hole's robust residual variance, ``s_cam`` the camera's blur (px, without the pixel).

    On the wall the residual's autocovariance is v_w delta(d) + v_g exp(-d^2 / (4 (c^2 +
    s^2))) (a Gaussian kernel of sigma c, then the camera's): its correlations at 1-3 px
    give c (within 0.3-2 px) and the grain's share.  None when too few wall pixels are
    read."""
    if int(wall_ok.sum()) < 200:
        return None
    vals = res_grid[wall_ok]
    med = float(np.median(vals))
    mad = 1.4826 * float(np.median(np.abs(vals - med)))
    ok = wall_ok & (np.abs(res_grid - med) <= 5.0 * max(mad, 1e-6))
    g = np.where(ok, res_grid - med, 0.0)
    var = float(np.mean(g[ok] ** 2))
    r = np.array([_lag_corr(g, ok, k) for k in (1, 2, 3)])
    # the wall's sensor variance is never below a quarter of the hole side's, nor the 8-bit
    # quantisation's 1/12 DN^2 (a noise-free wall read 3e-8 DN^2 once, and its pixels then
    # outweighed the hole's a million times: round 17)
    floor = max(0.25 * inner_var, QUANT_VAR_DN2)
    if not 0.02 < r[0] < 0.98:
        # no measurable correlation: white noise, no grain term
        return GrainNoise(inner_var, max(var, floor), 0.0, 0.0)
    # the grain's share f and its scale c: least squares of f exp(-d^2 / (4 (c^2 + s^2)))
    # over lags 1-3, c on a grid within what a fine grain can be (0.3-2 px)
    d2 = np.array([1.0, 4.0, 9.0])
    best = None
    for c in np.linspace(0.3, 2.0, 35):
        rho = np.exp(-d2 / (4.0 * (c * c + s_cam * s_cam)))
        f = float(np.clip(np.dot(rho, r) / np.dot(rho, rho), 0.0, 1.0))
        err = float(np.sum((r - f * rho) ** 2))
        if best is None or err < best[0]:
            best = (err, f, c)
    _, share, corr = best
    corr = float(corr)
    v_g = share * var
    return GrainNoise(inner_var, max(var - v_g, floor), v_g, corr)


def _blur(x: np.ndarray, sigma: float) -> np.ndarray:
    """Each layer of the stack x (k, h, w) through a Gaussian of ``sigma`` px, zero
    outside (cv2 in float32: a Gauss-Newton step needs no more)."""
    out = np.empty(x.shape, np.float32)
    for k in range(x.shape[0]):
        out[k] = cv2.GaussianBlur(np.ascontiguousarray(x[k], np.float32), (0, 0), sigma,
                                  borderType=cv2.BORDER_CONSTANT)
    return out


class NoiseOperator:
    """C on a hole's ROI grid, restricted to the fit's pixels (``sel``)."""

    def __init__(self, noise: GrainNoise, sel: np.ndarray, wall_share: np.ndarray, s_cam: float):
        self.sel = sel
        self.sensor = np.where(sel, noise.sensor_in_var + (noise.sensor_out_var - noise.sensor_in_var) * wall_share,
                               1.0)
        self.s_cam = float(s_cam)
        self.corr = float(noise.corr_px)
        self.on = noise.grain_var > 0 and self.corr > 0
        if self.on:
            # the grain's amplitude: a unit white field through K (sigma c) and B_s has a
            # per-pixel variance 1 / (4 pi (c^2 + s^2)) (continuous Gaussians), which the
            # measured grain variance fixes
            unit = 1.0 / (4.0 * np.pi * (self.corr**2 + self.s_cam**2))
            self.amp = np.sqrt(noise.grain_var / unit) * wall_share
        self.precond = 1.0 / (self.sensor + (noise.grain_var * wall_share if self.on else 0.0))

    def apply(self, x: np.ndarray) -> np.ndarray:
        """C x for a stack x (k, h, w) that is 0 off ``sel``."""
        out = self.sensor * x
        if self.on:
            e = _blur(x, self.s_cam) * self.amp
            e = _blur(e, self.corr * np.sqrt(2.0)) * self.amp  # K K^T: a Gaussian of sqrt(2) c
            out = out + _blur(e, self.s_cam)
        return out * self.sel

    def solve(self, b: np.ndarray, tol: float = 1e-3, max_iter: int = 200) -> np.ndarray:
        """C^-1 b for a stack b (k, h, w)."""
        return block_cg(self.apply, self.precond * self.sel, b, tol, max_iter)


def block_cg(apply, precond: np.ndarray, b: np.ndarray, tol: float = 1e-6, max_iter: int = 200) -> np.ndarray:
    """Solve C x = b for every layer of the stack b (k, h, w) by conjugate gradients,
    with ``apply(x)`` = C x for a stack and the Jacobi preconditioner ``precond`` (the
    inverse of C's diagonal, 0 off the pixels C lives on); until every layer's residual
    is within ``tol`` of its b's norm."""
    x = np.zeros_like(b)
    r = b.copy()
    z = precond * r
    p = z.copy()
    rz = np.einsum("kij,kij->k", r, z)
    b_norm = np.sqrt(np.einsum("kij,kij->k", b, b))
    for _ in range(max_iter):
        q = apply(p)
        pq = np.einsum("kij,kij->k", p, q)
        alpha = np.where(pq > 0, rz / np.where(pq > 0, pq, 1.0), 0.0)
        x += alpha[:, None, None] * p
        r -= alpha[:, None, None] * q
        if np.all(np.sqrt(np.einsum("kij,kij->k", r, r)) <= tol * b_norm):
            break
        z = precond * r
        rz_new = np.einsum("kij,kij->k", r, z)
        beta = np.where(rz > 0, rz_new / np.where(rz > 0, rz, 1.0), 0.0)
        p = z + beta[:, None, None] * p
        rz = rz_new
    return x
