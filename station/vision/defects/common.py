"""Small tools every stage of the defect detector uses: robust noise, confidence,
the hatch's directions, a bounded Gauss-Newton fit, shapes (Feret, weighted PCA), runs
along a profile and a blurred step's end.

Part of ``station.vision.defects`` (its docstring tells the method).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.special import ndtr

from station.vision.defects.config import DefectConfig


def mad_sigma(v: np.ndarray) -> float:
    """Robust standard deviation (MAD x 1.4826, exact for Gaussian data)."""
    v = v[np.isfinite(v)]
    if v.size == 0:
        return float("nan")
    if v.size > 40000:  # a median's precision needs no more (its relative error ~ 1/sqrt(n))
        v = v[:: v.size // 20000]
    m = np.median(v)
    return float(1.4826 * np.median(np.abs(v - m)))


def confidence_of(significance: float, threshold: float) -> float:
    """0..1 from a significance: 0.5 at the acceptance threshold, ~0.95 at 1.6x it."""
    return float(1.0 / (1.0 + np.exp(-(significance - threshold) / (0.2 * threshold))))


def circ_diff_deg(a: float, b: float, period: float = 180.0) -> float:
    return abs((a - b + period / 2) % period - period / 2)


def near_hatch(angle_deg: float, angles_deg, cfg: "DefectConfig") -> float | None:
    """The groove family (of ``angles_deg``) within ``cfg.groove_alignment_deg`` of
    ``angle_deg`` nearest it, or None."""
    near = [g for g in angles_deg if circ_diff_deg(angle_deg, g) < cfg.groove_alignment_deg]
    return min(near, key=lambda g: circ_diff_deg(angle_deg, g)) if near else None


def is_along_hatch(angle_deg: float, length_px: float, angles_deg, cfg: "DefectConfig") -> bool:
    """Whether a mark of direction ``angle_deg`` and length ``length_px`` runs along a
    groove family (``angles_deg``, the frame's two): within ``cfg.groove_alignment_deg``
    of one and, when the two are mirrored about the bore's axis as a hatch is (within
    ``cfg.hatch_mirror_deg``), crossing no more than ``cfg.hatch_cross_px`` of its lines
    over its length."""
    g = near_hatch(angle_deg, angles_deg, cfg)
    if g is None:
        return False
    if len(angles_deg) != 2 or circ_diff_deg(float(angles_deg[0]), -float(angles_deg[1])) > cfg.hatch_mirror_deg:
        return True  # the families read are not a mirrored pair: no line to cross is known
    return bool(length_px * np.sin(np.deg2rad(circ_diff_deg(angle_deg, g))) <= cfg.hatch_cross_px)


def on_groove_line(angle_deg: float, length_px: float, width_px: float, angles_deg,
                   cfg: "DefectConfig") -> float | None:
    """The groove family (of ``angles_deg``) one of whose lines a mark of direction
    ``angle_deg``, length ``length_px`` and width ``width_px`` keeps to over its length
    (its chord crossing no more than ``cfg.hatch_cross_px`` of the family's lines beyond
    its own width), the nearest in direction; or None. A mark's direction along the hatch
    is read loosely: a groove's piece 25 px long reads 8-14 deg off its family where its
    ends are cut obliquely or a neighbour's piece lies beside it (groove-breaks bench
    1650000: 10 of its 18 false scratches read 5-14 deg off), and two pieces side by side
    read as one mark as wide as their offset, its axis turned by it. No further off than
    ``cfg.groove_line_max_off_deg``: a short wide mark crosses few lines at any angle."""
    off = {g: circ_diff_deg(angle_deg, g) for g in angles_deg}
    fits = [g for g, d in off.items()
            if d <= cfg.groove_line_max_off_deg and length_px * np.sin(np.deg2rad(d)) <= cfg.hatch_cross_px + width_px]
    return min(fits, key=off.get) if fits else None


@dataclass
class FitResult:
    x: np.ndarray  # parameters
    cov: np.ndarray  # their covariance from the residual's robust scale
    fun: np.ndarray  # residuals at the solution


def gauss_newton(model, p0: np.ndarray, data: np.ndarray, lo: np.ndarray, hi: np.ndarray, iterations: int = 12,
                 huber_k: float = 2.0) -> FitResult:
    """A small bounded least-squares fit with Huber weights (IRLS): forward-difference
    Jacobian, normal equations with Levenberg damping, steps clipped to the bounds.
    scipy's trust-region solver spent 9 ms per step in an SVD of the Jacobian (several
    thousand pixels by 8 parameters) where the 8 x 8 normal equations take microseconds."""
    p = np.clip(np.asarray(p0, float), lo, hi)
    n = p.size
    lam = 1e-3
    f = model(p) - data
    scale = max(mad_sigma(f), 1e-6)

    def cost(res, sc):
        a = np.abs(res) / (huber_k * sc)
        return float(np.sum(np.where(a < 1, a * a, 2 * a - 1)))

    jac = np.empty((data.size, n))
    for _ in range(iterations):
        for j in range(n):
            h = 1e-4 * max(abs(p[j]), 1.0)
            q = p.copy()
            q[j] = min(q[j] + h, hi[j]) if q[j] + h <= hi[j] else q[j] - h
            jac[:, j] = (model(q) - data - f) / (q[j] - p[j])
        a = np.abs(f) / (huber_k * scale)
        w = np.where(a < 1, 1.0, 1.0 / np.maximum(a, 1e-12))
        jw = jac * w[:, None]
        g = jw.T @ f
        hmat = jw.T @ jac
        c0 = cost(f, scale)
        improved = False
        for _try in range(6):
            step = np.linalg.solve(hmat + lam * np.diag(np.diag(hmat) + 1e-12), -g)
            q = np.clip(p + step, lo, hi)
            fq = model(q) - data
            if cost(fq, scale) < c0:
                p, f = q, fq
                lam = max(lam / 3, 1e-7)
                improved = True
                break
            lam *= 10
        if not improved or np.all(np.abs(step) < 1e-6 * np.maximum(np.abs(p), 1.0)):
            break
        scale = max(mad_sigma(f), 1e-6)
    a = np.abs(f) / (huber_k * scale)
    w = np.where(a < 1, 1.0, 1.0 / np.maximum(a, 1e-12))
    hmat = (jac * w[:, None]).T @ jac
    try:
        cov = np.linalg.pinv(hmat) * float(np.sum(w * f * f)) / max(float(w.sum()) - n, 1.0)
    except np.linalg.LinAlgError:
        cov = np.full((n, n), np.inf)
    return FitResult(p, cov, f)


def feret(x: np.ndarray, y: np.ndarray, step_deg: float = 0.5) -> tuple[float, float, float]:
    """Greatest Feret diameter of a point set, its direction (deg, 0-180) and the extent
    across that direction."""
    a = np.deg2rad(np.arange(0.0, 180.0, step_deg))
    proj = np.cos(a)[:, None] * x[None, :] + np.sin(a)[:, None] * y[None, :]
    ext = proj.max(axis=1) - proj.min(axis=1)
    i = int(np.argmax(ext))
    across = -np.sin(a[i]) * x + np.cos(a[i]) * y
    return float(ext[i]), float(np.rad2deg(a[i])), float(across.max() - across.min())


def weighted_pca(xx: np.ndarray, yy: np.ndarray, wts: np.ndarray) -> tuple[float, float, float, np.ndarray]:
    """Centroid, direction of the major axis (rad) and the 2x2 covariance of a weighted point set."""
    sw = wts.sum()
    cx, cy = (wts * xx).sum() / sw, (wts * yy).sum() / sw
    dx, dy = xx - cx, yy - cy
    sxy = (wts * dx * dy).sum()
    cov = np.array([[(wts * dx * dx).sum(), sxy], [sxy, (wts * dy * dy).sum()]]) / sw
    evals, evecs = np.linalg.eigh(cov)
    return float(cx), float(cy), float(np.arctan2(evecs[1, 1], evecs[0, 1])), cov


def true_runs(mask: np.ndarray, wrap: bool) -> list[tuple[int, int]]:
    """(start, stop) index ranges of the True runs of a 1-D mask; with ``wrap`` a run
    may cross the end (stop > len)."""
    n = mask.size
    if not mask.any():
        return []
    if mask.all():
        return [(0, n)]
    idx = np.flatnonzero(np.diff(np.concatenate([[0], mask.astype(np.int8), [0]])))
    runs = [(int(a), int(b)) for a, b in zip(idx[::2], idx[1::2])]
    if wrap and len(runs) > 1 and runs[0][0] == 0 and runs[-1][1] == n:
        first = runs.pop(0)
        last = runs.pop()
        runs.append((last[0], n + first[1]))
    return runs


def fit_end(s: np.ndarray, data: np.ndarray, guess: float, blur: float, rising: bool,
            step_blur: float | None = None, height: float | None = None,
            noise: tuple[float, float] | None = None) -> tuple[float, float]:
    """Where a profile steps up (``rising``) or down near ``guess``: the crossing of half
    its *local* height, the height read 1.2 blur to 1.2 blur + 1 px inside the end
    (where a blurred step has reached 88-97 %), iterated from ``guess``. A ragged defect
    is often low at its ends; one height for the whole defect (a fitted box, or a step
    fitted over a window reaching into its middle) put such ends 1-2 px too far in. On
    the dev frames' 217 rim defects, lengths off by more than 10 % and 2 px: 24 with the
    height read 2-4 blur inside, 13 with 1.2 blur + 1 px. Returns (position, standard
    deviation from the noise at the crossing).

    ``step_blur``: the blur of a square end's step in ``data`` (Gaussian sigma, px), if it
    is one. The height read so near the end is the blurred step's 88-97 %, not its
    plateau, so its half sat outside the end: each end of a square-ended scratch (its
    profile smoothed over 1 px, a step blur of 1.7 px) read 0.2-0.3 px out, every
    scratch 0.55 px long on a clean wall. Given the step's blur, the height is divided by
    what the step reaches where it was read.

    ``height``: the profile's height at the end if known (a square-ended scratch's own
    level): its half is the crossing, not a local height's.

    ``noise``: for the crossing's u, the profile's standard deviation where no defect is
    and the blur of a step in it, both as smoothed (a pair). Without it the noise
    is read from the profile's sample-to-sample differences, which a profile smoothed
    over a few samples hides (at 1 px over 0.5 px samples the differences hold a quarter
    of its standard deviation), and which does not hold the texture's slow part."""
    order = np.argsort(s)
    s, data = s[order], data[order]
    inward = 1.0 if rising else -1.0
    end = guess
    half = 0.5
    for _ in range(4):
        near = (inward * (s - end) >= 1.2 * blur) & (inward * (s - end) <= 1.2 * blur + 1.0)
        if not near.any():
            break
        if height is not None:
            level = 0.5 * height
        else:
            level = 0.5 * float(np.median(data[near]))
            if step_blur is not None:
                level /= float(np.median(ndtr(inward * (s[near] - end) / step_blur)))
        if level <= 0:
            break
        half = level
        # the crossing nearest the current end, by linear interpolation, that steps the
        # way this end does: up into the defect at its start, down out of it at its end
        # (either way, a ragged chip's end was read on its other side and its length came
        # out negative: wide bench seed 78008, a 0.086 x 0.072 mm chip lost)
        above = data >= half
        cross = np.flatnonzero(above[1:] & ~above[:-1] if rising else above[:-1] & ~above[1:])
        if cross.size == 0:
            break
        i = cross[np.argmin(np.abs(s[cross] - end))]
        t = (half - data[i]) / (data[i + 1] - data[i]) if data[i + 1] != data[i] else 0.5
        new = float(s[i] + t * (s[i + 1] - s[i]))
        if abs(new - end) > 3.0 * blur + 3.0:
            break  # ran off: keep the walk's end
        end = new
    # the crossing moves by noise / slope; a blurred step of height 2 half has slope
    # 2 half / (sqrt(2 pi) blur) at its middle
    resid, slope_blur = (mad_sigma(np.diff(data)) / np.sqrt(2.0), blur) if noise is None else noise
    slope = 2.0 * half / (np.sqrt(2 * np.pi) * slope_blur)
    return end, float(resid / slope)
