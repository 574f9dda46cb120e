"""Circle and ellipse fits to sub-pixel edge points.

Why several stages: edge points along rays contain outliers (a honing groove crossing
the rim, a ray that locked onto the wrong edge), and an algebraic fit alone is biased
on short arcs (partial holes).  So: RANSAC over 3-point circles picks the consensus,
Taubin's algebraic fit on its inliers gives a nearly unbiased start, and a geometric
Gauss-Newton fit with Tukey biweights (IRLS) minimises the true orthogonal distances
while outliers lose their weight.  All of it is vectorised numpy on (N, 2) arrays.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: Tukey biweight tuning constant for 95 % efficiency under Gaussian noise
#: (Holland & Welsch 1977; the usual default in robust regression)
TUKEY_C = 4.685
#: MAD -> standard deviation for Gaussian data (1 / Phi^-1(3/4))
MAD_TO_SIGMA = 1.4826


def median(a: np.ndarray) -> float:
    """The median of an array, as ``np.median`` but without its per-call overhead.

    ``np.median`` costs ~30 us per call whatever the size; the fits call it a few times
    per iteration on a few hundred residuals, where that overhead was most of its time.
    """
    a = np.asarray(a).ravel()
    n = a.size
    k = n // 2
    if n % 2:
        return float(np.partition(a, k)[k])
    p = np.partition(a, (k - 1, k))
    return 0.5 * float(p[k - 1] + p[k])


@dataclass(frozen=True)
class CircleFit:
    cx: float
    cy: float
    r: float
    rms_px: float  # weighted RMS of orthogonal residuals of the inliers
    inliers: np.ndarray  # bool mask over the input points


def circle_from_3(p: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Circles through point triples ``p`` (M, 3, 2): centres x, y and radii (nan if collinear)."""
    a, b, c = p[:, 0], p[:, 1], p[:, 2]
    d = 2 * (a[:, 0] * (b[:, 1] - c[:, 1]) + b[:, 0] * (c[:, 1] - a[:, 1]) + c[:, 0] * (a[:, 1] - b[:, 1]))
    sa, sb, sc = (a**2).sum(1), (b**2).sum(1), (c**2).sum(1)
    with np.errstate(divide="ignore", invalid="ignore"):
        ux = (sa * (b[:, 1] - c[:, 1]) + sb * (c[:, 1] - a[:, 1]) + sc * (a[:, 1] - b[:, 1])) / d
        uy = (sa * (c[:, 0] - b[:, 0]) + sb * (a[:, 0] - c[:, 0]) + sc * (b[:, 0] - a[:, 0])) / d
    r = np.hypot(a[:, 0] - ux, a[:, 1] - uy)
    return ux, uy, r


def ransac_circle(
    pts: np.ndarray, threshold_px: float, rng: np.random.Generator, hypotheses: int = 96
) -> np.ndarray:
    """Inlier mask of the best of ``hypotheses`` random 3-point circles."""
    n = len(pts)
    idx = rng.integers(0, n, (hypotheses, 3))
    ux, uy, r = circle_from_3(pts[idx])
    # repeated indices give collinear (degenerate) triples: d = 0 -> nan radius
    ok = np.isfinite(r) & (idx[:, 0] != idx[:, 1]) & (idx[:, 1] != idx[:, 2]) & (idx[:, 0] != idx[:, 2])
    res = np.abs(np.hypot(pts[None, :, 0] - ux[:, None], pts[None, :, 1] - uy[:, None]) - r[:, None])
    counts = np.where(ok, (res < threshold_px).sum(1), -1)
    return res[int(np.argmax(counts))] < threshold_px


def taubin_circle(pts: np.ndarray, w: np.ndarray | None = None) -> tuple[float, float, float]:
    """Taubin's algebraic circle fit (G. Taubin, IEEE PAMI 13(11), 1991), optionally weighted.

    Less biased than Kasa's on short arcs, which matters for holes cut by the border.
    """
    w = np.ones(len(pts)) if w is None else w
    sw = w.sum()
    mx, my = (w * pts[:, 0]).sum() / sw, (w * pts[:, 1]).sum() / sw
    x, y = pts[:, 0] - mx, pts[:, 1] - my
    z = x * x + y * y
    zm = (w * z).sum() / sw
    z0 = (z - zm) / (2 * np.sqrt(zm))
    a = np.stack([z0, x, y], axis=1) * np.sqrt(w)[:, None]
    _, _, vt = np.linalg.svd(a, full_matrices=False)
    v = vt[2]
    a0 = v[0] / (2 * np.sqrt(zm))
    coeffs = np.array([a0, v[1], v[2], -zm * a0])
    cx = -coeffs[1] / (2 * coeffs[0]) + mx
    cy = -coeffs[2] / (2 * coeffs[0]) + my
    r = np.sqrt(coeffs[1] ** 2 + coeffs[2] ** 2 - 4 * coeffs[0] * coeffs[3]) / (2 * abs(coeffs[0]))
    return float(cx), float(cy), float(r)


def robust_circle(
    pts: np.ndarray,
    init: tuple[float, float, float] | None = None,
    min_scale_px: float = 0.05,
    iterations: int = 12,
    weights: np.ndarray | None = None,
    oval: bool = False,
) -> CircleFit:
    """Geometric circle fit with Tukey IRLS, from ``init`` or Taubin's fit.

    ``weights`` (0..1) are prior weights per point, multiplied into Tukey's.
    ``oval`` adds a second harmonic to the radius, r(theta) = r + a cos 2theta +
    b sin 2theta: an ellipse to first order in its ovality, so that a slightly oval
    hole's extremes are not taken for outliers and ``r`` is its mean radius.
    ``min_scale_px`` floors the robust residual scale so that clean data (residuals of
    a few hundredths of a pixel) do not have good points trimmed as outliers.
    """
    cx, cy, r = init if init is not None else taubin_circle(pts)
    h2 = np.zeros(2)  # second-harmonic amplitudes (cos, sin)
    prior = np.ones(len(pts)) if weights is None else weights
    w = prior.copy()
    px, py = pts[:, 0], pts[:, 1]
    used_mask = prior > 0
    # the Jacobian's columns are written in place each iteration (few hundred points: the
    # loop's cost is numpy's per-call overhead, so every call saved counts)
    jac = np.empty((5 if oval else 3, len(pts)))
    jac[2] = -1.0
    for it in range(iterations):
        dx, dy = px - cx, py - cy
        d = np.sqrt(dx * dx + dy * dy)
        np.maximum(d, 1e-9, out=d)
        res = d - r
        np.divide(dx, d, out=jac[0])  # the unit radial direction (negated below)
        np.divide(dy, d, out=jac[1])
        if oval:
            # cos 2theta and sin 2theta of the point's angle, without arctan2
            np.subtract(jac[0] * jac[0], jac[1] * jac[1], out=jac[3])
            np.multiply(jac[0], jac[1], out=jac[4])
            jac[4] *= 2.0
            res -= h2[0] * jac[3] + h2[1] * jac[4]
        if it < 3:  # the scale settles once the gross outliers are out; then keep it
            used = res[used_mask]
            scale = max(MAD_TO_SIGMA * median(np.abs(used - median(used))), min_scale_px)
        # Tukey's biweight: (1 - u^2)^2 inside |u| < 1, 0 outside
        t = res * (1.0 / (TUKEY_C * scale))
        t *= t
        np.subtract(1.0, t, out=t)
        np.maximum(t, 0.0, out=t)
        w = prior * t * t
        if w.sum() < 3:
            break
        jac[0] *= -1.0
        jac[1] *= -1.0
        if oval:
            jac[3] *= -1.0
            jac[4] *= -1.0
        jw = jac * w
        try:
            step = np.linalg.solve(jw @ jac.T, -(jw @ res))
        except np.linalg.LinAlgError:
            break
        cx, cy, r = cx + step[0], cy + step[1], r + step[2]
        if oval:
            h2 = h2 + step[3:]
        if np.abs(step).max() < 1e-4:  # 1e-4 px: two orders below the accuracy sought
            break
    dx, dy = px - cx, py - cy
    d = np.maximum(np.sqrt(dx * dx + dy * dy), 1e-9)
    res = d - r
    if oval:
        res = res - (h2[0] * (dx * dx - dy * dy) + h2[1] * 2.0 * dx * dy) / (d * d)
    inl = w > 0
    rms = float(np.sqrt((w * res**2).sum() / max(w.sum(), 1e-9)))
    return CircleFit(float(cx), float(cy), float(r), rms, inl)


def fit_ellipse_direct(pts: np.ndarray) -> tuple[float, float, float, float, float] | None:
    """Fitzgibbon's direct least-squares ellipse (PAMI 21(5), 1999) in Halir-Flusser form.

    Returns (cx, cy, semi_major, semi_minor, angle_deg) or None when the points do not
    determine an ellipse.  Used to report ovality; the diameter comes from the circle.
    """
    if len(pts) < 6:
        return None
    m = pts.mean(0)
    s = max(float(pts.std()), 1e-9)
    x, y = (pts[:, 0] - m[0]) / s, (pts[:, 1] - m[1]) / s
    d1 = np.stack([x * x, x * y, y * y], 1)
    d2 = np.stack([x, y, np.ones_like(x)], 1)
    s1, s2, s3 = d1.T @ d1, d1.T @ d2, d2.T @ d2
    try:
        t = -np.linalg.solve(s3, s2.T)
    except np.linalg.LinAlgError:
        return None
    mm = s1 + s2 @ t
    mm = np.array([mm[2] / 2, -mm[1], mm[0] / 2])
    evals, evecs = np.linalg.eig(mm)
    evecs = np.real(evecs)
    cond = 4 * evecs[0] * evecs[2] - evecs[1] ** 2
    good = np.where(cond > 0)[0]
    if good.size == 0:
        return None
    a1 = evecs[:, good[0]]
    a, b, c = a1
    dd, ee, ff = t @ a1
    den = b * b - 4 * a * c
    if den >= 0:
        return None
    cx = (2 * c * dd - b * ee) / den
    cy = (2 * a * ee - b * dd) / den
    num = 2 * (a * ee * ee + c * dd * dd - b * dd * ee + den * ff)
    root = np.sqrt((a - c) ** 2 + b * b)
    with np.errstate(invalid="ignore"):
        ax1 = -np.sqrt(num * (a + c + root)) / den
        ax2 = -np.sqrt(num * (a + c - root)) / den
    if not (np.isfinite(ax1) and np.isfinite(ax2)):
        return None
    angle = 0.5 * np.arctan2(-b, c - a)
    major, minor = max(ax1, ax2), min(ax1, ax2)
    if ax2 > ax1:
        angle += np.pi / 2
    return (float(cx * s + m[0]), float(cy * s + m[1]), float(major * s), float(minor * s), float(np.rad2deg(angle) % 180))
