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
from numba import njit

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
    prior = np.ones(len(pts)) if weights is None else np.asarray(weights, dtype=np.float64)
    px = np.ascontiguousarray(pts[:, 0], dtype=np.float64)
    py = np.ascontiguousarray(pts[:, 1], dtype=np.float64)
    cx, cy, r, h0, h1, w = _irls_circle(px, py, prior, float(cx), float(cy), float(r), float(min_scale_px),
                                        int(iterations), bool(oval))
    dx, dy = px - cx, py - cy
    d = np.maximum(np.sqrt(dx * dx + dy * dy), 1e-9)
    res = d - r
    if oval:
        res = res - (h0 * (dx * dx - dy * dy) + h1 * 2.0 * dx * dy) / (d * d)
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


@njit(cache=True, nogil=True)
def gradient_1d(p: np.ndarray) -> np.ndarray:
    """``np.gradient`` of a 1-D array with unit spacing (central differences inside,
    one-sided at the ends), for the compiled kernels (numba has no np.gradient)."""
    n = p.size
    out = np.empty(n)
    out[0] = p[1] - p[0]
    out[n - 1] = p[n - 1] - p[n - 2]
    for j in range(1, n - 1):
        out[j] = 0.5 * (p[j + 1] - p[j - 1])
    return out


@njit(cache=True, nogil=True)
def solve_small(m: np.ndarray, v: np.ndarray):
    """Gaussian elimination with partial pivoting for the fits' 3x3 / 5x5 normal
    equations; (solution, False) when the matrix is singular."""
    k = v.size
    a = m.copy()
    b = v.copy()
    for col in range(k):
        p = col
        for row in range(col + 1, k):
            if abs(a[row, col]) > abs(a[p, col]):
                p = row
        if a[p, col] == 0.0 or not np.isfinite(a[p, col]):
            return b, False
        if p != col:
            for j in range(k):
                a[col, j], a[p, j] = a[p, j], a[col, j]
            b[col], b[p] = b[p], b[col]
        for row in range(col + 1, k):
            f = a[row, col] / a[col, col]
            for j in range(col, k):
                a[row, j] -= f * a[col, j]
            b[row] -= f * b[col]
    x = np.zeros(k)
    for row in range(k - 1, -1, -1):
        acc = b[row]
        for j in range(row + 1, k):
            acc -= a[row, j] * x[j]
        x[row] = acc / a[row, row]
    return x, True


@njit(cache=True, nogil=True)
def _irls_circle(px, py, prior, cx, cy, r, min_scale_px, iterations, oval):
    """The IRLS loop of ``robust_circle`` (Gauss-Newton steps on the orthogonal distances
    with Tukey's biweight times the prior weights; the robust scale re-estimated in the
    first three iterations).  Returns cx, cy, r, the second-harmonic amplitudes and the
    last weights.  (Compiled: a few hundred points per fit, where numpy's per-call
    overhead was most of the time.)"""
    n = px.size
    k = 5 if oval else 3
    h0 = 0.0
    h1 = 0.0
    w = prior.copy()
    res = np.empty(n)
    jac = np.empty((n, 5))
    n_used = 0
    for i in range(n):
        if prior[i] > 0:
            n_used += 1
    used = np.empty(n_used)
    scale = min_scale_px
    for it in range(iterations):
        for i in range(n):
            dx = px[i] - cx
            dy = py[i] - cy
            d = max(np.sqrt(dx * dx + dy * dy), 1e-9)
            ux = dx / d
            uy = dy / d
            e = d - r
            jac[i, 0] = -ux
            jac[i, 1] = -uy
            jac[i, 2] = -1.0
            if oval:
                c2 = ux * ux - uy * uy
                s2 = 2.0 * ux * uy
                e -= h0 * c2 + h1 * s2
                jac[i, 3] = -c2
                jac[i, 4] = -s2
            res[i] = e
        if it < 3:  # the scale settles once the gross outliers are out; then keep it
            j = 0
            for i in range(n):
                if prior[i] > 0:
                    used[j] = res[i]
                    j += 1
            med = np.median(used)
            scale = max(MAD_TO_SIGMA * np.median(np.abs(used - med)), min_scale_px)
        m = np.zeros((k, k))
        v = np.zeros(k)
        wsum = 0.0
        for i in range(n):
            t = res[i] / (TUKEY_C * scale)
            t = 1.0 - t * t
            wi = prior[i] * t * t if t > 0 else 0.0
            w[i] = wi
            wsum += wi
            if wi == 0.0:
                continue
            for a in range(k):
                wa = wi * jac[i, a]
                v[a] += wa * res[i]
                for b in range(a, k):
                    m[a, b] += wa * jac[i, b]
        if wsum < 3:
            break
        for a in range(k):
            for b in range(a):
                m[a, b] = m[b, a]
        step, solved = solve_small(m, -v)
        if not solved:
            break
        cx += step[0]
        cy += step[1]
        r += step[2]
        if oval:
            h0 += step[3]
            h1 += step[4]
        big = 0.0
        for a in range(k):
            big = max(big, abs(step[a]))
        if big < 1e-4:  # 1e-4 px: two orders below the accuracy sought
            break
    return cx, cy, r, h0, h1, w
