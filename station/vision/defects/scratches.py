"""Scratches: the main furrow, its centre line and amplitude along it, its extent and
ends, its width as a blurred box with the camera's blur, and the tests that tell a
scratch from the cross-hatch's residue.

Part of ``station.vision.defects`` (its docstring tells the method).
"""

from __future__ import annotations

import cv2
import numpy as np
from scipy.ndimage import gaussian_filter1d
from scipy.special import ndtr

from station.vision.defects.common import (
    circ_diff_deg, FitResult, fit_end, gauss_newton, mad_sigma, true_runs, weighted_pca,
)
from station.vision.defects.wall import Patch


def _strip(r: np.ndarray, cx: float, cy: float, ang: float, s: np.ndarray, n: np.ndarray,
           bend: np.ndarray | None = None) -> np.ndarray:
    """``r`` sampled on a grid along (``s``) and across (``n``) a line through (cx, cy)
    at ``ang`` (rad), the across offset shifted by ``bend(s)``; NaN outside ``r``."""
    ca, sa = np.cos(ang), np.sin(ang)
    nn = n[:, None] + (bend[None, :] if bend is not None else 0.0)
    mx = (cx + s[None, :] * ca - nn * sa).astype(np.float32)
    my = (cy + s[None, :] * sa + nn * ca).astype(np.float32)
    return cv2.remap(r.astype(np.float32), mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT,
                     borderValue=float("nan"))


def _nanmean_rows(a: np.ndarray) -> np.ndarray:
    """Mean of each row over its finite values (NaN where it has none), quietly."""
    fin = np.isfinite(a)
    cnt = fin.sum(axis=1)
    return np.where(cnt > 0, np.where(fin, a, 0.0).sum(axis=1) / np.maximum(cnt, 1), np.nan)


def _blurred_box(x, centre, width, blur):
    return ndtr((x - centre + width / 2.0) / blur) - ndtr((x - centre - width / 2.0) / blur)


def _scratch_extent(m: np.ndarray, step: float, gap_px: float = 0.0,
                    held: tuple[np.ndarray, tuple[int, int]] | None = None) -> tuple[int, int] | None:
    """The extent of a scratch's darkening ``m`` (integrated across it, sampled every
    ``step`` px along it): the interval [a, b) that a box fits best, i.e. that maximises
    S^2 / n (S the darkening it holds, n its samples; the least-squares box of free
    height), over all intervals at 1 px resolution. A faint scratch's profile dips to
    nothing here and there over several px (noise, grooves crossing its smooth floor):
    runs above 40 % of the plateau, gaps of up to 6 px bridged, still read a 199 px
    scratch as 119 px (dev frames); a box pays for a dip only what the dip lacks, and for
    a groove crossing beyond a gap the whole gap.

    ``held``: another read of the same strip (its profile, sampled as ``m``, and its
    extent there) whose gaps alone may split ``m`` inside that extent: the grooves'
    scaling of a profile (``measure_scratch``) is a correction, and where a groove runs
    beside a scratch rather than across it, it drives the residual there below zero and
    lifts a junction of grooves on the scratch 2-3x, so it made a gap the raw read does
    not have, and the lesser half of a 1.6 mm scratch was lost (the twin's 2170043)."""
    k = max(int(round(1.0 / step)), 1)
    n = m.size // k
    if n < 2:
        return None
    coarse = m[: n * k].reshape(n, k).sum(axis=1)
    bridge = None
    if held is not None:
        raw, (ra, rb) = held
        rc = raw[: n * k].reshape(n, k).sum(axis=1)
        ca, cb = ra // k, min(-(-rb // k), n)
        raw_gaps = _profile_gaps(rc[ca:cb], gap_px) if cb - ca >= 3 else None
        if raw_gaps is not None:
            # where the raw read is not in a gap of its own (the same rule, over its extent)
            bridge = np.zeros(n, bool)
            bridge[ca:cb] = True
            for ga, gb in raw_gaps:
                bridge[ca + ga:ca + gb] = False
    c = np.concatenate([[0.0], np.cumsum(coarse)])
    i, j = np.triu_indices(n + 1, 1)
    total = c[j] - c[i]
    score = np.where(total > 0, total * total / (j - i), -1.0)
    best = int(np.argmax(score))
    if score[best] <= 0:
        return None
    a, b = int(i[best]), int(j[best])
    # ... but not across a gap: where the darkening stays under a quarter of the box's
    # median over gap_px, the scratch is not there, whatever lies beyond. A box pays for
    # a gap only what it lacks, and a deep groove crossing 10 px past a scratch's end
    # (the twin's 10 % grooves, where the wall model's straight grooves meet their fading)
    # bought the gap and carried the end 28 px on. Of the pieces, the one holding most
    a, b = _largest_piece(coarse, a, b, gap_px, bridge)
    return a * k, b * k


def _profile_gaps(coarse: np.ndarray, gap_px: float) -> list[tuple[int, int]] | None:
    """The gaps of a 1 px profile: runs of at least ``gap_px`` under a quarter of its
    median, smoothed over 3 px (so one noisy pixel does not bridge a gap); None when
    its median is not above zero (no plateau to judge a gap against)."""
    plateau = float(np.median(coarse))
    if plateau <= 0:
        return None
    seg = np.convolve(coarse, np.ones(3) / 3.0, mode="same")
    return [(ga, gb) for ga, gb in true_runs(seg < 0.25 * plateau, False) if gb - ga >= gap_px]


def _largest_piece(coarse: np.ndarray, a: int, b: int, gap_px: float,
                   bridge: np.ndarray | None = None) -> tuple[int, int]:
    """[a, b) of a 1 px profile split at runs of at least ``gap_px`` under a quarter
    of its median (smoothed over 3 px, so one noisy pixel does not bridge a gap); the
    piece with the largest sum. ``bridge`` (over the whole profile): where no gap may
    split it (a gap mostly there is none)."""
    if b - a < 3 or gap_px <= 0:
        return a, b
    gaps = _profile_gaps(coarse[a:b], gap_px)
    if gaps is None:
        return a, b
    gaps = [(ga, gb) for ga, gb in gaps if ga > 0 and gb < b - a
            and not (bridge is not None and bridge[a + ga:a + gb].mean() > 0.5)]
    if not gaps:
        return a, b
    bounds = [0] + [v for g in gaps for v in g] + [b - a]
    pieces = [(bounds[2 * q], bounds[2 * q + 1]) for q in range(len(bounds) // 2)]
    best = max(pieces, key=lambda pq: float(np.clip(coarse[a + pq[0]:a + pq[1]], 0.0, None).sum()))
    return a + best[0], a + best[1]


#: a stretch that the grooves' scaling adds at a scratch's end is a shelf, not the
#: scratch, when it is at least ``SHELF_MIN_PX`` long, runs along a modelled groove
#: (``SHELF_MIN_GROOVE_SHARE`` of the scratch's level through the same filter), holds at
#: most ``SHELF_MAX_SHARE`` of the scratch's scaled darkening (medians) and does not
#: overlap it: ``_shelf_beyond``
SHELF_MAX_SHARE = 0.6
SHELF_MIN_GROOVE_SHARE = 0.25
SHELF_MIN_PX = 10.0


def _shelf_beyond(av: np.ndarray, groove_av: np.ndarray, a: int, b: int, core: tuple[int, int],
                  step: float) -> bool:
    """Whether the stretch ``[a, b)`` of a scratch's scaled amplitude ``av`` (sampled every
    ``step`` px), which the grooves' scaling added past the raw read's end, is a groove's
    shelf rather than the scratch: at least ``SHELF_MIN_PX`` long; along a groove, the
    modelled grooves through the scratch's filter (``groove_av``) at least
    ``SHELF_MIN_GROOVE_SHARE`` of the scratch's level there (medians; the level the median
    of ``av`` over the raw read's extent ``core``); and at a level of its own, its median
    at most ``SHELF_MAX_SHARE`` of the scratch's and its upper quartile under the
    scratch's lower quartile.

    A scratch's floor is one furrow of one reflectance, its width varying by ~15 % on a
    scale of 8 px, so where the scaling restores its darkness through a groove it crosses
    the stretch reads at the scratch's level. A groove that the scratch ends on at a
    shallow angle (10-15 deg, as the station's scratches cross the hatch) runs on along
    its line, and the scaling lifts the wall model's misfit of it to a shelf at about half
    the scratch's level, which a box of free height takes in for nothing (station frame
    110048: a 0.85 mm scratch read 1.82 mm, a false scratch and a miss; the groove through
    the filter 0.45 of the scratch's level, the stretch 0.55; its misfit did not rise with
    the modelled groove, so ``_groove_beyond_end`` let it stand). A faint scratch's own end
    may read as low where its centre line, continued straight past its region, leaves it,
    but no groove runs along it there (station frame 91044: 0.08 of its level)."""
    if (b - a) * step < SHELF_MIN_PX or core[1] - core[0] < 2:
        return False
    stretch, inside = av[a:b], av[core[0]:core[1]]
    med = float(np.median(inside))
    return bool(med > 0 and float(np.median(groove_av[a:b])) >= SHELF_MIN_GROOVE_SHARE * med
                and float(np.median(stretch)) <= SHELF_MAX_SHARE * med
                and float(np.percentile(stretch, 75)) < float(np.percentile(inside, 25)))


#: a scratch's centre line is a quintic, not a cubic, where its peaks span this far (px):
#: across much of a frame the lens's distortion bends it as well as its own modes
QUINTIC_BEND_PX = 400.0

#: the camera's blur (Gaussian sigma, px) as a scratch's measurement assumes it before
#: anything in the frame says more: the middle of the station's envelope (0.8-2 px) and a
#: standard deviation that spans it. Combined with what the scratch's own cross profile
#: and ends say (``_scratch_blur``); it decides the blur only when both are vague
BLUR_PRIOR_PX = (1.4, 0.6)


def _ends_blur(s: np.ndarray, a: np.ndarray, s1: float, s2: float) -> tuple[float, float] | None:
    """The blur along a scratch from its two ends: each a blurred step of its amplitude
    along it (a furrow ends in a cut), fitted for its width over +/-7 px; the two
    combined by their variances, less the strip's bilinear sampling (1/6 px^2). Returns
    (blur, its variance), or None when neither end could be fitted. ``a`` must not be
    smoothed along the scratch: a first version fitted the profile after a 1 px
    Gaussian and took only the sampling off, which read a 1.2 px blur as 1.6 px and
    the twin's thin scratches as a third of their width."""
    est = []
    for end, sign in ((s1, 1.0), (s2, -1.0)):
        sel = np.abs(s - end) <= 7.0
        if sel.sum() < 8:
            continue
        x, v = s[sel], a[sel]
        inner = sign * (x - end) > 2.0
        h0 = max(float(np.median(v[inner])) if inner.any() else float(v.max()), 1e-3)
        # with an offset: the wall's level, smoothed over 16 px, sinks a little under a
        # scratch, and the darkening outside its ends reads a few per cent negative
        lo = np.array([0.0, end - 2.0, 0.4, -0.5 * h0])
        hi = np.array([4.0 * h0, end + 2.0, 4.0, 0.5 * h0])
        fit = gauss_newton(lambda q: q[0] * ndtr(sign * (x - q[1]) / q[2]) + q[3], np.array([h0, end, 1.5, 0.0]), v,
                           lo, hi, iterations=15)
        # samples 0.5 px apart of a bilinear interpolation are correlated (twice the
        # variance), and the scratch's width varies along it on the scale of the fit's
        # window (its plateau is no step's): dev frames' errors were twice the spread
        # the fit states once more (robust sd of the z-scores 1.9-2.0)
        var = 8.0 * fit.cov[2, 2]
        if np.isfinite(var) and var > 0 and 0.45 < fit.x[2] < 3.9:
            est.append((float(fit.x[2]), float(var)))
    if not est:
        return None
    w = np.array([1.0 / v for _, v in est])
    value = float(np.sum(w * np.array([b for b, _ in est])) / w.sum())
    blur = float(np.sqrt(max(value * value - 1.0 / 6.0, 0.25)))
    return blur, float((value / blur) ** 2 / w.sum())


def _bend_function(coef: np.ndarray, lo: float, hi: float):
    """A scratch's centre line across its chord as a function of the position along it:
    the polynomial over [lo, hi], where the cross profiles' peaks fixed it, continued
    along its tangent beyond (a cubic extrapolated 30 px ran off into the wall); and
    its slope."""
    der = np.polyder(coef)

    def at(s):
        s = np.asarray(s, float)
        sc = np.clip(s, lo, hi)
        return np.polyval(coef, sc) + np.polyval(der, sc) * (s - sc)

    def slope(s):
        return np.polyval(der, np.clip(np.asarray(s, float), lo, hi))

    return at, slope


def _flanks_take_out(f: np.ndarray, flank: np.ndarray) -> np.ndarray:
    """A filter across a scratch, less a constant on its ``flank`` rows that makes it sum
    to zero: darkening as wide as the band then reads nothing."""
    return f - np.where(flank, f.sum() / flank.sum(), 0.0) if flank.any() else f


def _line_significance(st: np.ndarray, nu: np.ndarray, core: np.ndarray, sv: np.ndarray, s1: float, s2: float,
                       step: float, n0: float, width: float, blur: float, noise_box5: float) -> float:
    """A scratch's significance through its own model across: the strip ``st`` (rows at
    offsets ``nu`` across, columns at ``sv`` along, both ``step`` px apart) weighed row by
    row by the blurred box fitted across (centre ``n0``, ``width``, ``blur``), the flank
    rows (not ``core``) set to take out darkening as wide as the band, and summed from
    ``s1`` to ``s2``; over the per-pixel noise the box's significance takes (5 x the 5 x 5
    box mean's), i.e. the sum's standard deviation were that noise white. Without flank
    rows and for a box filling the core it is the box's significance; a thin line it reads
    higher (a 1.6 px line under 1.3 px of blur in a 14.5 px band and 5 px flanks: ~1.4x)."""
    f = _flanks_take_out(_blurred_box(nu, n0, width, blur), ~core)
    sel = (sv >= s1) & (sv <= s2)
    if not sel.any() or noise_box5 <= 0:
        return 0.0
    total = float(np.sum(f @ st[:, sel])) * step * step
    var = (5.0 * noise_box5) ** 2 * float(np.sum(f * f)) * step * max(s2 - s1, 1.0)
    return total / float(np.sqrt(var)) if var > 0 else 0.0


def _scratch_cross_fit(nv: np.ndarray, pv: np.ndarray, b: float, half_w: float, p0=None) -> FitResult:
    """The mean cross profile as a blurred box of blur ``b`` (px, the strip's sampling
    included): contrast, centre, width, offset. The contrast is at most 1: a relative
    darkness beyond it is no light at all (a thin scratch fitted without that bound
    traded its width for contrasts of 1.4-1.5)."""
    c0 = max(float(np.max(pv)), 1e-3)
    w0 = max(float(np.trapezoid(np.clip(pv, 0, None), nv)) / c0, 0.5)
    lo = np.array([0.0, -3.0, 0.2, -0.1])
    hi = np.array([1.0, 3.0, 2 * half_w, 0.1])
    start = np.array([c0, 0.0, w0, 0.0]) if p0 is None else np.asarray(p0, float)
    return gauss_newton(lambda p: p[0] * _blurred_box(nv, p[1], p[2], b) + p[3], np.clip(start, lo, hi), pv,
                        lo, hi, iterations=20, huber_k=10.0)


def _scratch_blur(nv: np.ndarray, pv: np.ndarray, half_w: float):
    """The camera's blur for a scratch in a frame that gives none (no hole, no
    calibration): what its mean cross profile says (a blurred box with a free blur: its
    shoulders fix the blur when the scratch is wide, its kurtosis when thin, to ~0.1 px
    on a scratch 100 px long) and the prior (``BLUR_PRIOR_PX``), combined by their
    variances; ``measure_scratch`` adds what its two ends say (``_ends_blur``: blurred
    steps, 0.2-0.4 px each). Returns (blur, its variance). The ends alone (the first
    version) read the twin's 1.2 px blur anywhere from 0.5 to 2 px, and its thin
    scratches' widths 50-70 % off."""
    est = [(BLUR_PRIOR_PX[0], BLUR_PRIOR_PX[1] ** 2)]
    c0 = max(float(np.max(pv)), 1e-3)
    w0 = max(float(np.trapezoid(np.clip(pv, 0, None), nv)) / c0, 0.5)
    lo = np.array([0.0, -3.0, 0.2, 0.45, -0.1])
    hi = np.array([1.0, 3.0, 2 * half_w, 4.0, 0.1])
    free = gauss_newton(lambda p: p[0] * _blurred_box(nv, p[1], p[2], p[3]) + p[4],
                        np.clip(np.array([c0, 0.0, w0, 1.5, 0.0]), lo, hi), pv, lo, hi, iterations=20, huber_k=10.0)
    bx, var = float(free.x[3]), float(free.cov[3, 3])
    if np.isfinite(var) and var > 0 and lo[3] + 0.05 < bx < hi[3] - 0.05:
        b = float(np.sqrt(max(bx * bx - 1.0 / 6.0, 0.25)))
        # the fit's variance x 5 and a 0.05 px floor: the centre line's wander and the width's
        # variation along the scratch shape the mean profile too (dev frames, 170 scratches
        # of the twin and the bench: errors 1.7-2.4 times the fit's standard deviation, and
        # wide scratches' blur read 0.05 px high)
        est.append((b, 5.0 * var * (bx / b) ** 2 + 0.05**2))
    w = np.array([1.0 / v for _, v in est])
    value = float(np.sum(w * np.array([b for b, _ in est])) / w.sum())
    return value, float(1.0 / w.sum())


#: how firmly (the slope's t, on 1 px samples) a scratch's amplitude beyond its raw end
#: must rise with the groove there to be read as the groove's, not the scratch's
GROOVE_BEYOND_END_T = 3.0


def _groove_beyond_end(raw: np.ndarray, groove: np.ndarray, a: int, b: int, step: float) -> bool:
    """Whether the stretch ``[a, b)`` past a scratch's end on its raw amplitude ``raw``
    (the residual matched-filtered across, no scaling for the grooves) is the wall
    model's misfit of a groove there (``groove``: the modelled grooves through the same
    filter) rather than the scratch running on. The scratch's floor is smooth: where it
    runs through a groove the residual *dips* by what the model took for the groove,
    whatever the groove's depth; where it is not, the residual is the model's misfit of
    the groove, which on a deep groove the model underreads *rises* with it. So a
    stretch whose amplitude rises with the groove (the least-squares slope over 1 px
    samples, its t at least ``GROOVE_BEYOND_END_T``) is the groove's. A stretch under
    4 px, or over which the groove hardly varies, says nothing (False)."""
    k = max(int(round(1.0 / step)), 1)
    if b - a < 4 * k:
        return False
    y, x = raw[a:b:k], groove[a:b:k]
    if y.size < 4 or float(np.ptp(x)) <= 0:
        return False
    X = np.column_stack([np.ones_like(x), x])
    coef, *_ = np.linalg.lstsq(X, y, rcond=None)
    r = y - X @ coef
    dof = y.size - 2
    if dof <= 0:
        return False
    cov = float(r @ r) / dof * np.linalg.pinv(X.T @ X)
    se = float(np.sqrt(max(cov[1, 1], 0.0)))
    return bool(coef[1] > 0 and (se == 0.0 or coef[1] / se >= GROOVE_BEYOND_END_T))


#: how far above a smooth floor's read a stretch past a scratch's raw end may lie, as a
#: share of the scratch's own level, and still be the scratch: ``_misfit_beyond_end``
MISFIT_BEYOND_END_SHARE = 0.5


def _misfit_beyond_end(raw: np.ndarray, groove: np.ndarray, a: int, b: int, own: float, step: float) -> bool:
    """Whether the stretch ``[a, b)`` past a scratch's end on its raw amplitude ``raw`` is
    the wall model's misfit of a groove deeper than the scratch rather than the scratch
    running through it: a scratch's floor is smooth, so where it runs through a groove the
    raw amplitude is its own level ``own`` less the modelled groove (``groove``, through
    the same filter), at or under zero on a groove deeper than it, whatever the model's
    misfit; a stretch whose raw amplitude lies above that by ``MISFIT_BEYOND_END_SHARE``
    of ``own`` (medians) is no furrow's floor but the groove's own darkness the model
    left. The grooves' scaling, clipped at 2.5 where the groove through the filter is 1.2
    to 2.5 times the scratch's level, lifted that misfit to the scratch's level beyond a
    1.86 mm scratch's end on a deep groove, and its end read 13 px on (whole-surface seed
    23400, its place 0.067 mm off); the raw amplitude there rises with the groove too
    little for ``_groove_beyond_end``. A stretch under 4 px says nothing (False)."""
    k = max(int(round(1.0 / step)), 1)
    if b - a < 4 * k or not own > 0:
        return False
    floor = own - groove[a:b]
    return bool(float(np.median(raw[a:b] - floor)) >= MISFIT_BEYOND_END_SHARE * own)


#: a stretch of a scratch's centre-line peaks at one end that is the groove it ends on:
#: at least ``HATCH_TAIL_MIN_PX`` long, within ``HATCH_TAIL_DEG`` of a groove family,
#: the rest (at least ``HATCH_TAIL_MIN_BODY_PX``) off the hatch, and the two straight
#: lines fitting the peaks ``HATCH_TAIL_MAX_SSE_SHARE`` or less of one line's squares
#: (``_hatch_tail``)
HATCH_TAIL_MIN_PX = 20.0
HATCH_TAIL_MIN_BODY_PX = 40.0
HATCH_TAIL_DEG = 3.0
HATCH_TAIL_MAX_SSE_SHARE = 0.25
#: ... and the tail's peaks (median) at most this share of the body's
HATCH_TAIL_MAX_AMPLITUDE_SHARE = 0.6
#: ... and a cubic through all the peaks no more than this many times better (its
#: weighted squares) than the two lines: a smooth bend is the scratch's own
HATCH_TAIL_MAX_CUBIC_GAIN = 4.0


def _hatch_tail(s: np.ndarray, c: np.ndarray, w: np.ndarray, ang: float, angles_deg,
                alignment_deg: float) -> tuple[np.ndarray, float, int] | None:
    """Which of a scratch's centre-line peaks (``s`` along its axis ``ang``, rad; ``c``
    across; weights ``w``) are a groove's straight stretch at one of its ends: (that mask,
    where along the axis the peaks leave the scratch's line for the groove's, the end: 0
    low s, 1 high s), or None.

    A scratch that ends on a deep groove at a shallow angle joins the groove's residue in
    one region, and the peaks run on along the groove; at 15-20 deg from the scratch the
    robust line's Tukey weights do not drop them, they drag it, and the cubic follows the
    groove (the twin's frame 2131037: a 1.33 mm scratch 17 deg off the groove it ends on
    read 2.36 mm). The peaks then lie on two straight lines that meet at the kink: the
    tail along a groove family (``angles_deg``, within ``HATCH_TAIL_DEG``) and the body
    off the hatch (``alignment_deg`` or more from each family). A scratch bends slowly
    (the renderer's modes: 1.2 % of its length) and never onto the hatch at a kink; one
    along the hatch is never cut here."""
    if s.size < 12 or not len(angles_deg):
        return None
    o = np.argsort(s)
    ss, cc, ww = s[o], c[o], np.maximum(w[o], 1e-12)

    def line_fit(sel: np.ndarray) -> tuple[float, float, float]:
        """Weighted least squares c = a + m s: (sum of squares, a, m)."""
        x, y, q = ss[sel], cc[sel], ww[sel]
        sw = q.sum()
        mx, my = (q * x).sum() / sw, (q * y).sum() / sw
        vx = (q * (x - mx) ** 2).sum()
        slope = (q * (x - mx) * (y - my)).sum() / vx if vx > 0 else 0.0
        r = y - my - slope * (x - mx)
        return float((q * r * r).sum()), float(my - slope * mx), float(slope)

    whole = line_fit(np.ones(ss.size, bool))[0]
    if whole <= 0:
        return None
    # the best split of the peaks into two straight lines; the tail then the part along
    # the hatch (at least HATCH_TAIL_MIN_PX), the body the other (HATCH_TAIL_MIN_BODY_PX)
    best = None
    for b in np.arange(ss[0] + HATCH_TAIL_MIN_PX, ss[-1] - HATCH_TAIL_MIN_PX + 1e-9, 2.0):
        low = ss < b
        if low.sum() < 4 or (~low).sum() < 4:
            continue
        fl, fh = line_fit(low), line_fit(~low)
        if best is None or fl[0] + fh[0] < best[0]:
            best = (fl[0] + fh[0], float(b), fl[2], fh[2])
    if best is None or best[0] > HATCH_TAIL_MAX_SSE_SHARE * whole:
        return None
    _, b, m_low, m_high = best
    deg = [float(np.rad2deg(ang + np.arctan(m)) % 180.0) for m in (m_low, m_high)]
    span = (b - ss[0], ss[-1] - b)
    for side in (0, 1):  # 0: the tail at the low end of s, 1: at the high end
        if span[side] >= HATCH_TAIL_MIN_PX and span[1 - side] >= HATCH_TAIL_MIN_BODY_PX and \
                any(circ_diff_deg(deg[side], g) <= HATCH_TAIL_DEG for g in angles_deg) and \
                all(circ_diff_deg(deg[1 - side], g) >= alignment_deg for g in angles_deg):
            break
    else:
        return None
    tail = ss < b if side == 0 else ss >= b
    # ... and fainter: the groove's stretch is what the wall model misses of it, the
    # scratch's darkness is whole along its length (its width varies by ~15 %). A scratch
    # along the hatch whose region took in a piece off it (a crossing's residue) split
    # there, its own long stretch the "tail" at 0.70-1.13 of the piece's peaks (along
    # the hatch 542000: six scratches cut to a third of their length); 2131037's groove
    # 0.53 of its scratch's
    if float(np.median(ww[tail])) > HATCH_TAIL_MAX_AMPLITUDE_SHARE * float(np.median(ww[~tail])):
        return None
    # ... and a kink, not the scratch's own bend: a scratch bends smoothly (the renderer's
    # two modes, 1.2 % of its length each, turn its ends by up to ~6 deg), which a cubic
    # follows to the noise, and one 10 deg off the hatch bent its last 48 px within 3 deg
    # of it and was cut to 1.33 of its 1.81 mm (station frame 88091: the two lines' squares
    # 8.5x the cubic's). Where the cubic fits HATCH_TAIL_MAX_CUBIC_GAIN times better than
    # the two lines, no tail (2131037: 0.23; the twin's 2134066, where a thin scratch
    # merges into a wide groove band: 1.95)
    cubic = np.polyfit(ss, cc, 3, w=np.sqrt(ww))
    r3 = cc - np.polyval(cubic, ss)
    if best[0] > HATCH_TAIL_MAX_CUBIC_GAIN * float((ww * r3 * r3).sum()):
        return None
    out = np.zeros(s.size, bool)
    out[o] = tail
    return out, float(b), side


def measure_scratch(patch: Patch, region: np.ndarray, blur_hint: float | None = None, angles_deg=(),
                    alignment_deg: float = 7.5):
    """A scratch: its centre line (a polynomial bend), its extent (``_scratch_extent``)
    and each end at half its local height (``fit_end``) on its amplitude along it (the
    strip matched-filtered across by its own mean cross profile), its mean width (that
    profile fitted as a blurred box), with standard uncertainties (px). ``angles_deg``:
    the frame's groove families, and ``alignment_deg`` how near one a direction is along
    it (``DefectConfig.groove_alignment_deg``): a groove's stretch the peaks run on along
    at an end is cut off (``_hatch_tail``); none given, none is."""
    r = patch.residual
    h, w = r.shape
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float64)
    wts = np.where(region, np.clip(r, 0.0, None), 0.0)
    if wts.sum() <= 0:
        return None
    xr, yr, wr = xx[region], yy[region], wts[region]
    cx, cy, ang, _ = weighted_pca(xr, yr, wr)
    # the main line: a deep groove's residue the scratch ends on joins its region as a
    # branch, and a 40 px branch at 60 deg dragged the strip's width, its centre line
    # and its end along it (the twin's frames: a 127 px scratch read 191 px). What lies
    # within a band round the axis (the scratch's half width and blur, and its bend: a
    # few per cent of its length) is the scratch; its axis again from that
    main = np.ones(xr.size, bool)
    for _ in range(2):
        along = (xr - cx) * np.cos(ang) + (yr - cy) * np.sin(ang)
        across = -(xr - cx) * np.sin(ang) + (yr - cy) * np.cos(ang)
        keep = np.abs(across) <= 8.0 + 0.03 * float(np.ptp(along[main]))
        if keep.sum() < 8 or wr[keep].sum() <= 0:
            break
        main = keep
        cx, cy, ang, _ = weighted_pca(xr[main], yr[main], wr[main])
    ca, sa = np.cos(ang), np.sin(ang)
    along = (xr[main] - cx) * ca + (yr[main] - cy) * sa
    across = -(xr[main] - cx) * sa + (yr[main] - cy) * ca
    half_w = max(float(np.percentile(np.abs(across), 98)) + 6.0, 8.0)
    step = 0.5
    # beyond the region's ends by 30 px: a faint scratch's region, grown at full resolution,
    # may stop short of its end; and 5 px more each side, the flanks of the matched filter
    s = np.arange(along.min() - 30.0, along.max() + 30.0 + step, step)
    n_all = np.arange(-half_w - 5.0, half_w + 5.0 + step / 2, step)
    strip_all = _strip(r, cx, cy, ang, s, n_all)
    inside_w = np.abs(n_all) <= half_w + 1e-9
    n, strip = n_all[inside_w], strip_all[inside_w]
    # the centre line: column by column, the peak of the cross profile (smoothed over 1 px
    # each way, refined by a parabola), and a polynomial through the peaks with Tukey
    # weights. The darkening's centroid across was pulled by groove residue and noise
    # beside a faint scratch, and the polynomial with it (dev frames: 13 px widths)
    sm = cv2.GaussianBlur(np.nan_to_num(strip).astype(np.float32), (0, 0), 2.0, 2.0)
    sm[~np.isfinite(strip)] = -np.inf
    k = np.argmax(sm, axis=0)
    cols = np.arange(s.size)
    top = sm[k, cols]
    km, kp = np.clip(k - 1, 0, n.size - 1), np.clip(k + 1, 0, n.size - 1)
    y0_, y1_, y2_ = sm[km, cols], top, sm[kp, cols]
    with np.errstate(all="ignore"):
        den = y0_ - 2 * y1_ + y2_
        off = np.where(np.isfinite(den) & (den < 0), 0.5 * (y0_ - y2_) / den, 0.0)
    centre_n = n[k] + np.clip(off, -0.5, 0.5) * step
    col_mass = np.clip(top, 0.0, None)
    # the peaks are fitted over the region's length only: beyond its ends they are the
    # wall's (noise, or the groove a scratch ends on), and the line continues straight
    good = (np.isfinite(top) & (top > 3.0 * patch.noise / 2.0) & (s >= along.min() - 4.0)
            & (s <= along.max() + 4.0))
    if good.sum() < 4:
        return None
    # ... and only where they keep to a straight line, within the bend a scratch has (a few
    # per cent of its length): a groove's residue a scratch ends on leaves it at a shallow
    # angle, and the cubic followed it (bench frames: a 171 px scratch, a groove 25 deg off
    # its end, read 213 px). The line robustly (Tukey weights), then the peaks near it
    tail = _hatch_tail(s[good], centre_n[good], col_mass[good], ang, angles_deg, alignment_deg)
    if tail is not None:
        idx = np.flatnonzero(good)
        good[idx[tail[0]]] = False
    wts = np.sqrt(col_mass[good])
    sg, cg = s[good], centre_n[good]
    for _ in range(5):
        line = np.polyfit(sg, cg, 1, w=wts)
        res = cg - np.polyval(line, sg)
        u = res / (4.685 * max(mad_sigma(res), 0.5))
        wts = np.sqrt(col_mass[good]) * np.where(np.abs(u) < 1, (1 - u * u) ** 2, 0.0)
        if (wts > 0).sum() <= 3:
            break
    near = np.abs(centre_n - np.polyval(line, s)) <= 3.0 + 0.03 * float(np.ptp(sg))
    if (good & near).sum() >= 4:
        good &= near
    # a cubic: a dragged chip's path bends in up to two modes over its length (the
    # renderer's: sin(pi u) and sin(2 pi u), 1.2 % of the length each), which a quadratic
    # leaves as a wander of ~1-2 px on a 150 px scratch, smearing its cross profile
    deg = 3 if good.sum() >= 40 else (2 if good.sum() >= 12 else 1)
    if deg == 3 and float(np.ptp(s[good])) >= QUINTIC_BEND_PX:
        # a quintic over a long stretch: the lens bends a straight furrow across the frame
        # as r^3 and r^5 do, and with a long scratch's own modes a cubic over 950 px stood
        # 2-4.5 px off its last 40 px, where the matched filter then read nothing (a whole-
        # surface part's 12.2 mm scratch, a frame's piece of it 45 px short)
        deg = 5
    wts = np.sqrt(col_mass[good])
    for _ in range(4):
        coef = np.polyfit(s[good], centre_n[good], deg, w=wts)
        res = centre_n[good] - np.polyval(coef, s[good])
        u = res / (4.685 * max(mad_sigma(res), 0.3))
        wts = np.sqrt(col_mass[good]) * np.where(np.abs(u) < 1, (1 - u * u) ** 2, 0.0)
        if (wts > 0).sum() <= deg + 2:
            break
    bend_at, slope_at = _bend_function(coef, float(s[good].min()), float(s[good].max()))
    bend = bend_at(s)
    strip_all = _strip(r, cx, cy, ang, s, n_all, bend)
    strip = strip_all[inside_w]
    prof_all = _nanmean_rows(strip[:, good])
    if not np.isfinite(prof_all).any():
        return None
    # integrate across over the scratch's core and its blur (where the mean profile is dark)
    core_half = max(float(np.sum(prof_all > 0.5 * np.nanmax(prof_all))) * step / 2.0 + 5.0, 4.0)
    core_all = np.abs(n_all) <= core_half
    core = core_all[inside_w]
    # the amplitude along the scratch: each column matched-filtered by the mean cross
    # profile (its least-squares multiple), less the mean of 5 px flanks each side. Across
    # the core's 10-15 px the box integral took in as much groove residue and grain as
    # scratch on a thin one, and a deep groove crossing the strip darkens its whole width
    # (the twin's grooves, 10 % deep: a 1.6 px scratch ran on 45 px past its end, a 127 px
    # one on 64 px); the filter weighs each pixel by what the scratch puts there, and
    # darkening as wide as the flanks cancels. A straight furrow's square end blurred by
    # a Gaussian is separable, so the amplitude steps at the end as the darkening does
    flank = (np.abs(n_all) > core_half) & (np.abs(n_all) <= core_half + 5.0)
    used = core_all | flank
    valid = np.isfinite(strip_all[used]).all(axis=0)
    if valid.sum() < 8:
        return None
    filt = np.where(core_all, np.nan_to_num(np.clip(_nanmean_rows(strip_all[:, good]), 0.0, None)), 0.0)
    if filt.sum() <= 0:
        return None
    filt_norm = float(np.sum(filt * filt))
    filt = _flanks_take_out(filt, flank)[used]
    sv = s[valid]
    used_strip = strip_all[used][:, valid]
    box_rows = core_all[used]
    grooves = np.nan_to_num(_strip(patch.grooves, cx, cy, ang, s, n_all[used], bend)[:, valid])

    def profiles(factor):
        st = used_strip if factor is None else used_strip * factor
        return np.sum(st[box_rows], axis=0) * step, (filt @ st) / filt_norm

    mv, av = profiles(None)
    gap_px = 8.0
    ext = _scratch_extent(av, step, gap_px)
    if ext is None:
        return None
    s1, s2 = float(sv[ext[0]]), float(sv[ext[1] - 1])
    if s2 - s1 < 3.0:
        return None
    # the mean profile across, over the scratch's length clear of its ends
    inner = (s >= s1 + 2.0) & (s <= s2 - 2.0)
    prof = _nanmean_rows(strip[:, inner])
    ok = np.isfinite(prof)
    if ok.sum() < 5:
        return None
    nv, pv = n[ok], prof[ok]
    # across a thin scratch, its width and contrast trade off under the blur (their product
    # is what the profile fixes); the blur comes from the frame's holes (``blur_hint``)
    # when it has any, else from the scratch itself: its cross profile and the prior here,
    # its ends below (``_scratch_blur``, ``_ends_blur``)
    if blur_hint is not None:
        # given (the frame's holes, a calibration: exact), or shared by the frame's scratches
        # (``KnownBlur``: its variance carried into the width below)
        blur_cam, var_blur = float(np.clip(blur_hint, 0.5, 3.5)), float(getattr(blur_hint, "var", 0.0))
    else:
        blur_cam, var_blur = _scratch_blur(nv, pv, half_w)

    def cross_fit(blur_cam):
        # the strip's bilinear sampling, at phases that vary along the scratch, adds the
        # variance of a tent (1/6 px^2) to the averaged cross profile
        b = float(np.sqrt(float(np.clip(blur_cam, 0.5, 3.5)) ** 2 + 1.0 / 6.0))
        return b, _scratch_cross_fit(nv, pv, b, half_w)

    b, cross = cross_fit(blur_cam)
    c = float(cross.x[0])
    # the furrow's floor is smooth: the honing grooves the wall model subtracts are not in
    # it, so where a groove G crosses the scratch the residual reads cover x (c - G) rather
    # than cover x c (dev frames: a faint 1.6 px scratch broke into pieces at deep
    # grooves). Each pixel scaled by c / (c - G), which is 1 off the scratch: the first
    # version added G x width along the centre line, also past the ends, where a deep
    # groove then carried the end on (the twin's frames)
    c_eff = float(np.clip(max(c, float(np.nanmax(prof_all))), 0.05, 1.0))
    factor = c_eff / np.maximum(c_eff - grooves, c_eff / 2.5)
    ext_raw, av_raw = ext, av
    groove_ends = [False, False]  # an end read where a groove's stretch begins
    groove_av = (filt @ grooves) / filt_norm  # the modelled grooves through the same filter
    mv, av = profiles(factor)
    ext = _scratch_extent(av, step, gap_px, held=(av_raw, ext_raw))
    if ext is not None:
        # ... but an end that the scaling carried on into a groove the scratch ends on is
        # the raw darkness's: there the scaling lifts the wall model's misfit of the groove
        # (``_groove_beyond_end``; a whole-surface part's 0.89 mm scratch ending on a deep
        # groove 30 deg off it read 1.06 mm, its place 0.10 mm off), or lifts it to a shelf
        # below the scratch's own level (``_shelf_beyond``)
        lo, hi = ext
        trim = int(np.ceil(2.0 * b / step))  # the raw end's own blurred step
        # ... or lifts a deep groove's misfit that lies above what a smooth floor would
        # leave through it (``_misfit_beyond_end``)
        own_raw = float(np.median(av_raw[ext_raw[0]:ext_raw[1]])) if ext_raw[1] > ext_raw[0] else 0.0
        if _groove_beyond_end(av_raw, groove_av, ext[0], ext_raw[0] - trim, step) \
                or _shelf_beyond(av, groove_av, ext[0], ext_raw[0], ext_raw, step) \
                or _misfit_beyond_end(av_raw, groove_av, ext[0], ext_raw[0] - trim, own_raw, step):
            lo = ext_raw[0]
            av[:lo] = av_raw[:lo]
            groove_ends[0] = True
        if _groove_beyond_end(av_raw, groove_av, ext_raw[1] + trim, ext[1], step) \
                or _shelf_beyond(av, groove_av, ext_raw[1], ext[1], ext_raw, step) \
                or _misfit_beyond_end(av_raw, groove_av, ext_raw[1] + trim, ext[1], own_raw, step):
            hi = ext_raw[1]
            av[hi:] = av_raw[hi:]
            groove_ends[1] = True
        ext = (lo, hi)
        s1, s2 = float(sv[ext[0]]), float(sv[ext[1] - 1])
    if tail is not None:
        # the scratch ends where it meets the groove its peaks ran on along (``_hatch_tail``):
        # beyond, the darkness is the groove's, which the straight line read for ~15 px as it
        # left it (the twin's 2131037 read 10 % long and 0.07 mm off)
        meet, side = tail[1], tail[2]
        beyond = sv < meet if side == 0 else sv > meet
        av = np.where(beyond, np.minimum(av, 0.0), av)
        groove_ends[side] = True
        if side == 0:
            s1 = max(s1, meet)
        else:
            s2 = min(s2, meet)
        if s2 - s1 < 3.0:
            return None
    if blur_hint is None:
        ends = _ends_blur(sv, av, s1, s2)
        if ends is not None:
            wb = 1.0 / var_blur + 1.0 / ends[1]
            blur_cam = (blur_cam / var_blur + ends[0] / ends[1]) / wb
            var_blur = 1.0 / wb
            b, cross = cross_fit(blur_cam)
    c, n0, width, _ = (float(v) for v in cross.x)
    var_w = float(cross.cov[2, 2]) if np.isfinite(cross.cov[2, 2]) else width**2
    if var_blur > 0:
        # the blur's own uncertainty, carried into the width by the fit's sensitivity to it
        db = 0.1
        bb = float(np.sqrt((float(np.clip(blur_cam, 0.5, 3.5)) + db) ** 2 + 1.0 / 6.0))
        dw = (float(_scratch_cross_fit(nv, pv, bb, half_w, cross.x).x[2]) - width) / db
        var_w += dw * dw * var_blur
    blur_x = b
    blur = float(np.clip(blur_x, 0.7, 2.8))
    ms = gaussian_filter1d(av, 1.0 / step)
    # a square end's step in ms: the camera's blur and the strip's sampling (blur_x), and
    # the 1 px smoothing
    step_blur = float(np.hypot(blur_x, 1.0))
    s1, u_s1 = fit_end(sv, ms, s1, blur, rising=True, step_blur=step_blur)
    s2, u_s2 = fit_end(sv, ms, s2, blur, rising=False, step_blur=step_blur)
    # ... each end read at half its local height, which walks out along a shelf past a
    # square end: where the scratch ends on a deep groove crossing it, the model's misfit
    # of the groove beyond holds a third of the scratch's level, and read on it the half
    # height fell onto the shelf, and again, 10-15 px on (the twin's 2133057: a 1.22 mm
    # scratch read 1.37 mm, 0.07 mm off; the raw read's end right). An end that went 10 px
    # or more past the raw read's over a shelf (``_shelf_beyond``) is read at half the
    # scratch's own level instead, from the raw read's end
    if tail is None:
        own = float(np.median(av[ext_raw[0]:ext_raw[1]])) if ext_raw[1] > ext_raw[0] else 0.0
        lo_raw, hi_raw = float(sv[ext_raw[0]]), float(sv[ext_raw[1] - 1])
        k1 = int(np.searchsorted(sv, s1))
        if own > 0 and _shelf_beyond(av, groove_av, k1, ext_raw[0], ext_raw, step):
            s1, u_s1 = fit_end(sv, ms, lo_raw, blur, rising=True, height=own)
        k2 = int(np.searchsorted(sv, s2, side="right"))
        if own > 0 and _shelf_beyond(av, groove_av, ext_raw[1], k2, ext_raw, step):
            s2, u_s2 = fit_end(sv, ms, hi_raw, blur, rising=False, height=own)
    if s2 - s1 < 3.0:
        return None
    ss = np.linspace(s1, s2, 200)
    length = float(np.trapezoid(np.sqrt(1.0 + slope_at(ss) ** 2), ss))
    # the width's spread from the fit's covariance: its product with the contrast is what
    # the profile fixes best, the two apart only as well as the blur is known
    u_width = float(np.sqrt(max(var_w, 0.0)))
    mid = (s1 + s2) / 2.0
    nm = float(bend_at(mid)) + n0
    x = cx + mid * ca - nm * sa
    y = cy + mid * sa + nm * ca
    area = float(np.sum(core)) * step * max(s2 - s1, 1.0)
    mass = float(np.sum(mv[(sv >= s1) & (sv <= s2)]) * step)
    significance = mass / (5.0 * patch.noise_box5 * np.sqrt(area))
    # ... and through the scratch's own model across (its fitted blurred box, the flanks
    # taking out what is as wide as they are), over the same noise: the box's band is the
    # mean profile's FWHM and 5 px each side, which a thin line fills about a quarter of
    line_significance = _line_significance(used_strip * factor, n_all[used], box_rows, sv, s1, s2, step,
                                           n0, width, b, patch.noise_box5)
    # the chord's direction (the centre line's mean slope over the scratch; its slope at
    # the middle, the first version's, is off the chord by up to 5-10 deg on a scratch bent
    # in an S, and a 137 deg scratch read 144 deg and was taken for the 150 deg hatch)
    direction = float(np.rad2deg(ang + np.arctan(float(bend_at(s2) - bend_at(s1)) / (s2 - s1))) % 180.0)
    # the patch cuts the scratch when its strip runs out of the patch (not out of the
    # samples asked for) within reach of an end
    reach = 3.0 * blur + 4.0
    cut = bool((sv[0] > s[0] + 1e-6 and s1 - sv[0] < reach) or (sv[-1] < s[-1] - 1e-6 and sv[-1] - s2 < reach))
    sl = np.linspace(s1, s2, max(int((s2 - s1) / 5.0), 2) + 1)
    nl = bend_at(sl) + n0
    line = (cx + sl * ca - nl * sa, cy + sl * sa + nl * ca)
    return dict(x=float(x), y=float(y), length=length, width=width, angle=direction,
                u_length=float(np.hypot(u_s1, u_s2)), u_width=u_width, significance=float(significance),
                line_significance=float(line_significance),
                contrast=c, blur=blur_x, mean_darkness=float(np.max(pv)), cut=cut, line=line,
                blur_read=None if blur_hint is not None else (float(blur_cam), float(var_blur)),
                groove_ends=(bool(groove_ends[0]), bool(groove_ends[1])),
                half_band=float(width / 2.0 + 2.5 * blur + 2.0))
