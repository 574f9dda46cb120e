"""Burrs and chips at every hole's edge: rays from the hole's centre, the share of
"hole" along each, the rim's edge, its low harmonics taken off, and each run of edge
moved in (a burr) or out (a chip) measured and tested against the grooves.

Part of ``station.vision.defects`` (its docstring tells the method).
"""

from __future__ import annotations

from dataclasses import dataclass
import itertools
import warnings

import cv2
import numpy as np
from scipy.ndimage import gaussian_filter1d, maximum_filter1d
from scipy.special import ndtr, ndtri

from station.vision.edges import SMOOTH_SIGMA_PX
from station.vision.defects.config import (Defect, DefectConfig, RIM_FLOOR_CROSSING, RIM_HOLD_PX,
                                          RIM_RING_MIN_SAMPLES)
from station.vision.defects.common import confidence_of, fit_end, mad_sigma, true_runs
from station.vision.defects.wall import groove_profiles, fit_plane


@dataclass
class _RimProfile:
    theta: np.ndarray  # ray directions (rad, image sense), 0.5 px of arc apart at the rim
    rr: np.ndarray  # radii sampled along each ray (px)
    share: np.ndarray  # (len(rr), len(theta)): the share of "hole", (W - I) / (W - H)
    valid: np.ndarray  # rays whose band is inside the frame and clear of the other zones, its wall's level read
    edge: np.ndarray  # per ray: where the share first falls below ``rim_crossing``, going out
    edge_find: np.ndarray  # the same on the share averaged along the rim (finding defects)
    #: per ray: where the share averaged along the rim first falls below ``RIM_FLOOR_CROSSING``,
    #: going out: the outer end of whatever is darker than the wall there (a chip whose
    #: floor is lit stays below ``rim_crossing`` and does not move ``edge``)
    edge_out: np.ndarray | None = None


def _rim_profile(img: np.ndarray, hole, zone_others: np.ndarray, reach_px: float, wall_level: np.ndarray,
                 angles_deg, blur_px: float, crossing: float, smooth_px: float, groove_sides: bool):
    """The rim along rays from the hole's centre: the share of "hole" (W - I) / (W - H)
    over [R - reach, R + reach], and each ray's edge, where that share first falls
    below ``crossing`` going out (``edge``; ``edge_find`` on the share averaged along
    the rim over ``smooth_px`` of arc first).

    W is the frame's wall level (``wall_level``, full res: it follows the blotches,
    carried over the hole's zone from the wall round it), recalibrated per angle on a
    ring just outside the band; H the hole's own level read per angle inside it. The
    edge is where the hole's dark disc ends, whatever lies inside it (a burr's bright
    metal) or beyond it (a chip's dark notch); a groove or a blotch on the wall moves it
    only when it touches the rim, where an integral of the share across the whole band
    took in every groove within reach (dev frames: 1-4 px on clean rims crossed by deep
    grooves, which the grooves' model, fitted on a ring further out, could not remove
    where they fade along their length)."""
    cx, cy, rad = hole.x_px, hole.y_px, hole.diameter_px / 2.0
    hh, ww = img.shape
    out_px = reach_px + 10.0
    box_px = out_px + 12.0
    x0, x1 = max(int(np.floor(cx - rad - box_px)), 0), min(int(np.ceil(cx + rad + box_px)) + 1, ww)
    y0, y1 = max(int(np.floor(cy - rad - box_px)), 0), min(int(np.ceil(cy + rad + box_px)) + 1, hh)
    p = img[y0:y1, x0:x1].astype(np.float32)
    level = np.ascontiguousarray(wall_level[y0:y1, x0:x1], dtype=np.float32)
    others = zone_others[y0:y1, x0:x1].astype(np.float32)
    # the cross-hatch, modelled on a ring beyond the band and read back along its lines
    # (as the photometric hole fit does); the hole cuts the grooves before the camera
    # blurs them, so they are put back outside the rim only
    yy, xx = np.mgrid[y0:y1, x0:x1].astype(np.float32)
    rho = np.hypot(xx - cx, yy - cy)
    fit_ring = (rho > rad + reach_px + 1.0) & (rho < rad + out_px + 12.0) & (others == 0)
    if fit_ring.sum() > 100:
        d = 1.0 - p / np.maximum(level, 1.0)
        d -= fit_plane(d, xx - x0, yy - y0, fit_ring)
        grooves = groove_profiles(d, xx, yy, fit_ring, angles_deg, sides_about=(cx, cy) if groove_sides else None)
        cover = ndtr((rho - rad) / max(blur_px, 0.5)).astype(np.float32)
        inside = rho < rad - 2.5 * max(blur_px, 0.5) - 1.0
        if inside.sum() >= 50:
            cover = groove_cover(p, level, level * grooves, float(np.median(p[inside])), cover, blur_px)
        p = p + level * grooves * cover
    step = 0.5
    n_th = int(np.ceil(2 * np.pi * rad / step))
    theta = np.linspace(0.0, 2 * np.pi, n_th, endpoint=False)
    rr = np.arange(rad - reach_px - 6.0, rad + reach_px + 9.0 + step / 2, step)
    mx = (cx - x0 + rr[:, None] * np.cos(theta)[None, :]).astype(np.float32)
    my = (cy - y0 + rr[:, None] * np.sin(theta)[None, :]).astype(np.float32)
    nan = float("nan")
    polar = cv2.remap(p, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=nan)
    wall_polar = cv2.remap(level, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=nan)
    other_polar = cv2.remap(others, mx, my, cv2.INTER_NEAREST, borderMode=cv2.BORDER_CONSTANT, borderValue=0.0)
    # the ring calibrates the wall's level per ray; it reads only wall clear of the other
    # zones and of their blurred skirts (2.5 blur + 1 px)
    others_skirt = grow_by_skirt(others, max(blur_px, 0.5))
    other_ring = cv2.remap(others_skirt, mx, my, cv2.INTER_NEAREST, borderMode=cv2.BORDER_CONSTANT, borderValue=0.0)
    inner = rr < rad - reach_px
    band = (rr >= rad - reach_px) & (rr <= rad + reach_px)
    ring = rr > rad + reach_px + 1.0
    with np.errstate(all="ignore"), warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # a column all outside the frame: NaN, dropped below
        hole_lv = np.nanmedian(polar[inner], axis=0)
        ring_wall = np.where(other_ring[ring] == 0, polar[ring] / wall_polar[ring], nan)
        ratio = np.nanmedian(ring_wall, axis=0)
    has_ratio = np.isfinite(ring_wall).sum(axis=0) >= RIM_RING_MIN_SAMPLES
    # a ray is read where its band is whole and clear of the other zones. Its wall's
    # level comes from its own ring or, where another zone (a pore, a scratch, another
    # hole) covers that ring, from the rays either side within ``reach_px`` of arc: a
    # 0.41 mm pore 24 px off a rim covered the ring over a chip's middle, and the rays
    # left out there cut the chip in two (station envelope, seed 680052)
    valid = (np.isfinite(polar[band]).all(axis=0) & np.isfinite(hole_lv)
             & (other_polar[band].max(axis=0) == 0))
    if valid.sum() < 16 or has_ratio.sum() < 16:
        return None
    valid &= _arc_distance(has_ratio, step) <= reach_px

    def smooth(v: np.ndarray, px: float, ok: np.ndarray | None = None) -> np.ndarray:
        ok = valid if ok is None else ok
        filled = np.interp(np.arange(n_th), np.flatnonzero(ok), v[ok], period=n_th)
        return gaussian_filter1d(filled, px / step, mode="wrap")

    # the hole's far side varies slowly round it (vignetting) and has no texture: its
    # level smoothed over ~10 px of arc; the wall's recalibration over 4 px of arc
    hole_s = smooth(hole_lv, 10.0)
    wall_b = wall_polar[band] * smooth(ratio, 4.0, has_ratio)[None, :]
    share = (wall_b - polar[band]) / np.maximum(wall_b - hole_s[None, :], 1.0)
    share[:, ~valid] = 0.0
    rb = rr[band]
    share = _lift_wall(share, rb, valid, rad + 2.5 * blur_px + 1.0, smooth)

    def first_crossing(sh: np.ndarray, crossing: float = crossing) -> np.ndarray:
        # the first fall below ``crossing``, going out, that holds over ``RIM_HOLD_PX``
        # (past the band's end counts as below: the wall; a ray already below it at the
        # band's start, and held: the edge is there)
        below = sh < crossing
        for j in range(1, int(round(RIM_HOLD_PX / step)) + 1):
            below[:-j] &= sh[j:] < crossing
        k = np.argmax(below, axis=0)
        k = np.where(below.any(axis=0), k, rb.size - 1)
        km = np.maximum(k - 1, 0)
        cols = np.arange(n_th)
        s0, s1 = sh[km, cols], sh[k, cols]
        t = np.where(k > 0, (s0 - crossing) / np.maximum(s0 - s1, 1e-6), 0.0)
        e = rb[km] + np.clip(t, 0.0, 1.0) * step
        e = np.where(k > 0, e, rb[0])
        e[~valid] = np.nan
        return e

    edge = first_crossing(share)
    # for finding defects, the crossing of the share averaged along the rim first: a first
    # crossing is a threshold's, and on a dim, noisy frame one noisy pixel moves a ray's
    # edge by pixels (inwards mostly, where the blurred step is brightest), which the
    # edge's smoothing afterwards cannot undo (a normalised average over the valid rays)
    edge_find, sh = edge, share
    if smooth_px > 0:
        sig = smooth_px / (2 * np.pi * rad / n_th)
        mode = "wrap" if valid.all() else "constant"
        w = gaussian_filter1d(valid.astype(np.float64), sig, mode=mode)
        sh = gaussian_filter1d(np.where(valid[None, :], share, 0.0), sig, axis=1, mode=mode)
        sh = sh / np.maximum(w, 1e-6)[None, :]
        edge_find = first_crossing(sh)
    edge_out = first_crossing(sh, RIM_FLOOR_CROSSING)
    edge_out[~(sh < RIM_FLOOR_CROSSING).any(axis=0)] = np.nan  # never left it within the band: not read
    return _RimProfile(theta, rb, share, valid, edge, edge_find, edge_out)


def groove_cover(img: np.ndarray, wall: np.ndarray, grooves_dn: np.ndarray, hole_dn: float,
                 beyond: np.ndarray, blur_px: float) -> np.ndarray:
    """Where a hole's grooves are put back: ``beyond`` (the circle's blurred outside,
    0 to 1) less what, beyond the rim's blurred step, is clearly no honed wall. A chip's
    floor is smooth fracture, and grooves put back over it at the wall's full depth lifted
    a lit floor (15 % of the step) over the rim's crossing, so a 0.10 x 0.05 mm chip
    crossed by two grooves read as no chip at all (station seed 981006).

    Each pixel is unmixed between the hole's level and the wall's less twice its grooves
    modelled (``grooves_dn``, >= 0; the model of a groove that fades along its length is
    off by up to its own size): I = H + m (W - 2 G - H). A pixel beyond the step
    (``beyond`` 0.95 and more; from 0.8 it comes in linearly) whose m is under 0.3 is as
    dark as the hole and takes no grooves back; over 0.6 it is wall and takes them all,
    linear between. Within the step nothing changes: the rim's edge is read there, at a
    wall share of 0.25, and deep grooves along or into a rim, their model's error carried
    into the unmixing, read as 0.19-0.34 mm chips (wide clean frames 1960012, 1985037,
    with a first version of this). Nor where twice the grooves take three quarters of the
    step or more: the unmixing divides by W - 2 G - H and would magnify the model's error
    beyond what the pixel tells; below 0.6 of the step it counts in full, linear between."""
    step = np.maximum(wall - hole_dn, 1.0)
    den = step - 2.0 * np.maximum(grooves_dn, 0.0)
    trust = np.clip((den / step - 0.25) / 0.15, 0.0, 1.0)
    m = (img - hole_dn) / np.maximum(den, 0.25 * step)
    m = cv2.GaussianBlur(m.astype(np.float32), (0, 0), max(0.7 * blur_px, 0.5), borderType=cv2.BORDER_REFLECT)
    dark = np.clip((0.6 - m) / 0.3, 0.0, 1.0) * trust
    far = np.clip((beyond - 0.8) / 0.15, 0.0, 1.0)
    return (beyond * (1.0 - far * dark)).astype(np.float32)


def grow_by_skirt(mask: np.ndarray, blur: float) -> np.ndarray:
    """``mask`` (an image, non-zero where the marks are) grown by a dark mark's blurred
    skirt, 2.5 blur + 1 px: how far a mark darkens the wall beyond its region."""
    skirt = int(np.ceil(2.5 * blur + 1.0))
    return cv2.dilate(mask, cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * skirt + 1, 2 * skirt + 1)))


def _arc_distance(ok: np.ndarray, step: float) -> np.ndarray:
    """Per ray (``step`` px of arc apart, round the whole rim): the arc to the nearest ray
    where ``ok`` holds (0 on those)."""
    n = ok.size
    idx = np.flatnonzero(ok)
    if idx.size == 0:
        return np.full(n, np.inf)
    k = np.arange(n)
    pos = np.searchsorted(idx, k)
    after = idx[pos % idx.size] + np.where(pos == idx.size, n, 0)
    before = idx[pos - 1] - np.where(pos == 0, n, 0)
    return np.minimum(after - k, k - before) * step


def _lift_wall(share: np.ndarray, rb: np.ndarray, valid: np.ndarray, beyond: float, smooth) -> np.ndarray:
    """The share with the wall's level raised, ray by ray, where the wall just beyond
    the rim (radii from ``beyond`` to the band's end, past the blurred step) reads
    brighter than the level it was calibrated to: its median share there ``e`` < 0,
    averaged along the rim (``smooth``, 4 px of arc) and taken where it exceeds twice its
    own spread round the rim. With the level W' = W - e (W - H) the share is (s - e) /
    (1 - e): the blurred step 1 - (1 - e) Phi, the edge's crossing moved in by the
    mis-read wall, becomes 1 - Phi again, and the hole's side (s = 1) is unchanged.

    Why: the wall's level is calibrated on a ring beyond the band and the grooves put back
    from a model fitted there; where a groove that is deep on that ring fades beside the
    rim, or a dark spot lies on the ring, the wall at the rim is brighter than its level
    (a share of -1.2 over 40 deg of arc), and the edge's crossing moved in by 1.1 px over
    21 px: a false 0.21 mm "burr" at significance 157 on a clean frame (wide bench seed
    86000, frame 25). Only brighter: a wall darker than its level is what a chip is, and
    nothing on the wall beyond a rim is brighter than the wall."""
    outer = rb >= beyond
    if outer.sum() < 3 or valid.sum() < 16:
        return share
    e = np.median(share[outer], axis=0)  # every column finite: unread rays are 0
    e_s = smooth(e, 4.0)
    spread = mad_sigma(e_s[valid])
    lift = np.minimum(e_s + 2.0 * spread, 0.0)
    lift[~valid] = 0.0
    if not (lift < 0).any():
        return share
    return (share - lift[None, :]) / (1.0 - lift[None, :])


def _rim_integral(prof: _RimProfile, lower: np.ndarray, upper: np.ndarray) -> np.ndarray:
    """Per ray, the equivalent edge over [lower, upper]: lower + the share of hole
    integrated over it. Blur moves light along a ray, not in or out of the interval,
    so this is the area-true edge however thin the feature (rays' own bands)."""
    return lower + _band_sum(prof.rr, prof.share, lower, upper)


def _band_sum(rr: np.ndarray, values: np.ndarray, lower: np.ndarray, upper: np.ndarray) -> np.ndarray:
    """Per ray (column of ``values``, sampled at radii ``rr``), the integral of the values
    over [lower, upper] (px), the samples taken as cells of the radii's step."""
    step = rr[1] - rr[0]
    cum = np.vstack([np.zeros(values.shape[1]), np.cumsum(values, axis=0) * step])
    pos = np.concatenate([[rr[0] - step / 2], rr + step / 2])  # cumulative sums' abscissae
    cols = np.arange(values.shape[1])

    def at(r):
        f = np.clip((r - pos[0]) / step, 0.0, pos.size - 1.000001)
        i = f.astype(np.int64)
        w = f - i
        return cum[i, cols] * (1 - w) + cum[np.minimum(i + 1, pos.size - 1), cols] * w

    return at(upper) - at(lower)


def _harmonic_basis(theta: np.ndarray, order: int) -> np.ndarray:
    """Columns 1, cos k theta, sin k theta for k = 1 .. ``order``."""
    cols = [np.ones_like(theta)]
    for k in range(1, order + 1):
        cols += [np.cos(k * theta), np.sin(k * theta)]
    return np.column_stack(cols)


def _robust_harmonics(theta: np.ndarray, edge: np.ndarray, valid: np.ndarray, order: int) -> np.ndarray:
    """The rim's low harmonics at each ray (``_robust_harmonic_coefs``)."""
    return _harmonic_basis(theta, order) @ _robust_harmonic_coefs(theta, edge, valid, order)


def _robust_harmonic_coefs(theta: np.ndarray, edge: np.ndarray, valid: np.ndarray, order: int) -> np.ndarray:
    """The rim's low harmonics (centre offset, ovality) fitted with Tukey weights, so a
    defect on part of the rim does not move them: their coefficients on
    ``_harmonic_basis`` (mean, cos theta, sin theta, ...).

    The weights' scale comes from the profile's own small-scale noise (differences over
    4 px of arc), not from the residuals of a first least-squares fit: defects on a
    quarter of the rim (two long burrs of a bench frame) pulled that fit, inflated its
    residuals' spread and with it the scale, and were then fitted away (dev frames).
    The fit starts from the median radius, so the defects begin as outliers."""
    a = _harmonic_basis(theta, order)
    y = np.nan_to_num(edge)
    lag = max(int(round(4.0 / (2 * np.pi * max(float(np.nanmean(edge)), 1.0) / theta.size))), 1)
    both = valid & np.roll(valid, -lag)
    local = mad_sigma((np.roll(y, -lag) - y)[both]) / np.sqrt(2.0)
    # a clean rim wanders by ~0.1-0.3 px where grooves cross it; a measured centre may be
    # off by 1-2 px (a first harmonic of that size; two large burrs pull the hole's fit):
    # the weights' reach shrinks from 3.7 px to the noise's over the first passes, so
    # the rim's clean rays are kept while the harmonics settle (dev frames: two burrs
    # on a quarter of a rim left a false "chip" between them with a fixed 1.6 px reach)
    scale = max(local, 0.1)
    coef = np.zeros(a.shape[1])
    coef[0] = float(np.median(y[valid]))
    reach = (0.8, 0.6, 0.45, 0.35)
    coef = _tukey_refine(a, y, valid, coef, [4.685 * max(scale, reach[it] if it < len(reach) else 0.0)
                                             for it in range(10)])
    if order != 1:
        return coef
    # ... but where defects take a large share of one side of the rim and the measured
    # centre is off, the fit can settle between the defects and the clean arc beside
    # them: two long burrs and a chip on 140 deg of a rim pulled the hole's fit 1.9 px off
    # (fresh station frame 4560076), the harmonics then ran through the burrs (first
    # harmonic 1.0 px for 1.9) and both burrs, 0.26 and 0.28 mm, were lost. Circles
    # through three of twelve sectors' median edges are tried too: the one the most of the
    # rim agrees with (Tukey's loss at the final reach), refined, stands where it
    # explains the rim better
    c_final = 4.685 * scale  # the last passes' reach
    cands = _sector_circles(theta, y, valid)
    if cands.shape[1]:
        losses = _tukey_loss(y[valid, None] - a[valid] @ cands, c_final)
        k = int(np.argmin(losses))
        current = _tukey_loss((y - a @ coef)[valid], c_final)
        if losses[k] < current:
            refined = _tukey_refine(a, y, valid, cands[:, k], [c_final] * 6)
            if _tukey_loss((y - a @ refined)[valid], c_final) < current:
                coef = refined
    return coef


@dataclass(frozen=True)
class _RimCircle:
    """The rim's circle as its baseline gives it: the hole's measured centre moved by the
    baseline's first harmonic, and the radius of the share's crossing moved out by where
    a blurred step crosses it. Large rim defects pull the hole's own fit (its rays' and
    its photometric disc's): two burrs and a chip on 150 deg of a rim put the centre 1.6
    px off and the radius 0.9 px short (wide frame 4600078), and a defect's arc read about
    that centre was 5-10 % short where the centre moved away from it (burrs push the
    fitted rim away) and long where it moved towards it (chips). Over 50 wide / 50
    station frames, holes with rim defects: centre RMS error 0.50 / 0.49 px for the
    hole's fit, 0.11 / 0.06 px for the baseline's; radius RMS 0.19 / 0.19 px and 0.14 /
    0.09 px (its bias -0.12 / -0.07 px, 0.3 % of an arc's length). Clean holes: the fit
    is better (0.03 px), but there the two agree within 0.1 px."""

    x: float
    y: float
    radius: float
    offset: tuple[float, float, float]  # the baseline's (mean, cos, sin) about the hole's centre
    n: int

    @classmethod
    def of(cls, hole, coef: np.ndarray, n: int, blur: float, crossing: float) -> "_RimCircle":
        """``coef``: the baseline's first harmonic (``_robust_harmonic_coefs``) over ``n`` rays."""
        r0, ox, oy = (float(v) for v in coef[:3])
        radius = r0 + float(ndtri(crossing)) * blur
        if not (np.isfinite(radius) and radius > 0 and np.hypot(ox, oy) < 0.25 * radius):
            r0, ox, oy, radius = hole.diameter_px / 2.0, 0.0, 0.0, hole.diameter_px / 2.0
        return cls(hole.x_px + ox, hole.y_px + oy, radius, (r0, ox, oy), n)

    def arc(self, i: float) -> float:
        """Arc length along the circle (px, from angle 0 about its centre, running on past
        2 pi as the rays' index does) of the rim's point on ray ``i`` (fractional index)
        of the rays from the hole's measured centre."""
        t = 2.0 * np.pi * i / self.n
        r0, ox, oy = self.offset
        b = r0 + ox * np.cos(t) + oy * np.sin(t)
        psi = np.angle(np.exp(1j * (np.arctan2(b * np.sin(t) - oy, b * np.cos(t) - ox) - t)))
        return float(self.radius * (t + psi))


def _tukey_refine(a: np.ndarray, y: np.ndarray, valid: np.ndarray, coef: np.ndarray, reaches) -> np.ndarray:
    """Iteratively reweighted least squares with Tukey's biweight, one reach per pass."""
    for c in reaches:
        u = (y - a @ coef) / c
        w = np.where(valid & (np.abs(u) < 1), (1 - u**2) ** 2, 0.0)
        if w.sum() < a.shape[1] * 3:
            break
        sw = np.sqrt(w)
        coef = np.linalg.lstsq(a * sw[:, None], y * sw, rcond=None)[0]
    return coef


def _tukey_loss(res: np.ndarray, c: float):
    """Tukey's biweight loss of the residuals at reach ``c`` (1 beyond it), summed over
    the first axis (one loss per column of a 2-D ``res``)."""
    u2 = np.minimum((res / c) ** 2, 1.0)
    return (1.0 - (1.0 - u2) ** 3).sum(axis=0)


def _sector_circles(theta: np.ndarray, y: np.ndarray, valid: np.ndarray, sectors: int = 12) -> np.ndarray:
    """The first-harmonic fits (mean, cos, sin) through every three sectors' median
    edges (sectors of the rim with at least 5 rays read, not nearly collinear), as the
    columns of a 3 x K array."""
    sec = np.floor((theta % (2 * np.pi)) / (2 * np.pi) * sectors).astype(int)
    rows = []
    for k in range(sectors):
        m = valid & (sec == k)
        if m.sum() >= 5:
            rows.append(([1.0, float(np.median(np.cos(theta[m]))), float(np.median(np.sin(theta[m])))],
                         float(np.median(y[m]))))
    tri = np.array(list(itertools.combinations(range(len(rows)), 3)), dtype=int).reshape(-1, 3)
    if not tri.size:
        return np.zeros((3, 0))
    a3 = np.array([r[0] for r in rows])[tri]  # K x 3 x 3
    y3 = np.array([r[1] for r in rows])[tri]  # K x 3
    ok = np.abs(np.linalg.det(a3)) >= 0.3
    if not ok.any():
        return np.zeros((3, 0))
    return np.linalg.solve(a3[ok], y3[ok][..., None])[..., 0].T


def camera_blur_from_edge(edge_sigma_px: float) -> float:
    """The camera's blur (Gaussian sigma, px) from a hole's measured rim: the rays' edge
    profile width (``HoleMeasurement.edge_sigma_px``) less the measurer's 1 px smoothing
    and the 1/6 px^2 of bilinear sampling (``station.vision.measure``), never below
    0.5 px; dev frames: within ~0.05 px of the rendered blur.

    Public because the blur is the camera's, not the frame's: the coverage scan reads it
    at the holes' edges during the bore scan and gives it to every surface frame
    (``detect_defects(blur_px=...)``), most of which show no hole to read it from."""
    return float(np.sqrt(max(edge_sigma_px**2 - SMOOTH_SIGMA_PX**2 - 1.0 / 6.0, 0.25)))


def hole_blur(hole) -> float:
    """The camera's blur at a hole's rim (px): :func:`camera_blur_from_edge` of its
    ``edge_sigma_px``."""
    return camera_blur_from_edge(hole.edge_sigma_px)


def rim_blur(hole) -> float:
    """The blur a hole's rim is read with (px): :func:`hole_blur` where its edge was
    measured, else 1.3 px (the station's camera)."""
    return hole_blur(hole) if getattr(hole, "edge_sigma_px", None) else 1.3


def marks_mask(shape: tuple[int, int], found, blur: float) -> np.ndarray:
    """The frame's pores and scratches found, each as its measured ellipse (length by
    width along its direction) grown by its blurred skirt (3 blur + 2 px): whole, where
    their claimed regions stop at a hole's zone (``_groove_run_on`` must not read a pore
    beside a rim as a groove's darkness running on)."""
    mask = np.zeros(shape, np.uint8)
    pad = 3.0 * blur + 2.0
    for d in found:
        if d.kind not in ("pore", "scratch"):
            continue
        axes = (int(np.ceil(d.length_px / 2.0 + pad)), int(np.ceil(d.width_px / 2.0 + pad)))
        cv2.ellipse(mask, (int(round(d.x_px)), int(round(d.y_px))), axes, float(d.angle_deg), 0.0, 360.0, 1, -1)
    return mask.astype(bool)


def _rim_noise(dev: np.ndarray, k: float, rounds: int = 4) -> float:
    """The noise of a rim's edge about its circle (px): the robust spread (MAD) of the
    deviations, read again without those that stand out at ``k`` times it, until it
    settles. The MAD alone is robust to a few defects, not to a rim that is half defect:
    two burrs and two chips over 42 % of a 0.75 mm hole's rim read a noise of 0.62 px
    (clean rims there: 0.05-0.17), and the chips, 2.5 and 3.5 px high, stayed under the
    5-noise bar (station bench seed 93005); without the burrs it reads 0.17 px. On a
    rim without defects nothing stands out at k noise, and the first reading stands."""
    noise = max(mad_sigma(dev), 0.02)
    for _ in range(rounds):
        inside = np.abs(dev) < k * noise
        if inside.sum() < 10 or inside.all():
            break
        new = max(mad_sigma(dev[inside]), 0.02)
        if abs(new - noise) <= 1e-3 * noise:
            break
        noise = new
    return noise


def rim_defects(img: np.ndarray, hole, index: int, zone_others: np.ndarray, wall_level: np.ndarray, angles_deg,
                cfg: DefectConfig, mm_per_px: float, marks: np.ndarray | None = None) -> list[Defect]:
    """Burrs and chips on one hole's rim: where the rim's edge stands out of its own
    low harmonics, inwards (burr) or outwards (chip). ``marks``: the frame's pores and
    scratches found (``marks_mask``), which a chip's run-on test does not read."""
    blur = rim_blur(hole)
    reach = cfg.rim_reach_mm / mm_per_px + 2.5 * blur + 2.0
    prof = _rim_profile(img, hole, zone_others, reach, wall_level, angles_deg, blur, cfg.rim_crossing,
                        cfg.rim_find_smooth_px, cfg.rim_groove_sides)
    if prof is None:
        return []
    theta, valid = prof.theta, prof.valid
    rad = hole.diameter_px / 2.0
    n = theta.size
    # the rays run on across theta = 0 when both ends are read: an arc left out elsewhere
    # (another hole's zone, a pore claimed beside the rim) does not cut the rim there, and
    # a defect across that point is one run (a burr at 0 deg on a rim with a pore's arc
    # left out was reported twice, as its two halves' runs)
    whole = bool(valid[0] and valid[-1])
    # the rim's baseline is a circle (the first harmonic: the measured centre's offset):
    # a second harmonic (ovality) bent round the arcs the defects take out of the fit
    # and read the clean rim between two burrs as a 3 px "chip" (dev: a quarter of a rim
    # under two burrs); a compensating hole's ovality on the bore is well under 1 px
    coef = _robust_harmonic_coefs(theta, prof.edge, valid, 1)
    base = _harmonic_basis(theta, 1) @ coef
    dev = np.where(valid, prof.edge - base, 0.0)
    circle = _RimCircle.of(hole, coef, theta.size, blur, cfg.rim_crossing)
    step_arc = 2 * np.pi * rad / n  # px of arc per ray
    # smoothed over ~1 px of arc: the rays are 0.5 px apart and the blur correlates them
    dev_s = gaussian_filter1d(dev, 1.0 / step_arc, mode="wrap" if whole else "nearest")
    noise = _rim_noise(dev_s[valid], cfg.rim_k)
    # the rays' edges on the share averaged along the rim, where a defect is looked for
    dev_f = np.where(valid, prof.edge_find - _robust_harmonics(theta, prof.edge_find, valid, 1), 0.0)
    dev_f = gaussian_filter1d(dev_f, 1.0 / step_arc, mode="wrap" if whole else "nearest")
    thr_f = max(cfg.rim_k * _rim_noise(dev_f[valid], cfg.rim_k), cfg.rim_min_height_px)
    # the area-true deviation, each ray integrated over its own edge and the baseline
    # plus the blur's reach: thin features (a burr lower than the blur) keep their area.
    # The ends and the significance are read on it; a chip's depth on the same integral
    # with the bands reaching out as far as whatever is darker than the wall (``area``):
    # a chip's lit floor stays below the edge's crossing, and its rays' bands ended
    # inside it (6.5 px read 3.2). The ends on the wider bands came out 1-3 px long on
    # short defects (dev frames).
    margin = 3.0 * blur + 1.0
    edge0 = np.nan_to_num(prof.edge, nan=0.0)
    clean = valid & (np.abs(dev_s) < 2.0 * noise)
    mode = "wrap" if whole else "nearest"

    def integral(lower: np.ndarray, upper: np.ndarray) -> np.ndarray:
        d = np.where(valid, _rim_integral(prof, lower, upper) - base, 0.0)
        # what the integral reads on the rim's clean rays (its small bias from the rim's
        # curvature and the band's texture), taken off
        return d - float(np.median(d[clean])) if clean.sum() > 10 else d

    lower, upper = np.minimum(edge0, base) - margin, np.maximum(edge0, base) + margin
    dev_int = integral(lower, upper)
    dev_int_s = gaussian_filter1d(dev_int, 1.0 / step_arc, mode=mode)
    # what moves an end's crossing: the smoothed profile's own spread on the clean rays
    # (the grain and the grooves where they meet the rim, the sensor's noise), against a
    # step blurred by the camera and the 1 px smoothing. The profile's sample-to-sample
    # differences (``fit_end``'s default) hold a quarter of it: a 1.2 px high burr's ends
    # read 1.2-1.5 px in at a u of 0.13 px (station 4800001, 4800045), burrs' lengths
    # within 2 u 90 % on station 4800000
    smoothed_blur = float(np.hypot(blur, 1.0))  # a step's blur in ``dev_int_s``
    end_noise = (mad_sigma(dev_int_s[clean]), smoothed_blur) if clean.sum() > 10 else None
    # out to 1.5 blur + 1 px past the floor's crossing (0.2, already ~0.8-1.5 blur past a
    # notch's end: 99.5 % of the blurred step; each px further only added noise, and a
    # shallow chip lost 0.3 px), the deepest within the blur's spill along the rim (its
    # light reaches the neighbours' rays); the extra reach read against the clean rays'
    # own share at each radius (the wall's ~0 reads -0.05 to -0.15 round some holes, lit
    # above the ring that calibrates it). For chips only: reaching inwards as well (a
    # deep narrow burr's spill) moved burrs' heights by -0.3 to +0.3 px at random, and the
    # outward reach, where a groove at the rim carries the floor's crossing out, lifted a
    # dim rim's dent over the significance bar as a false 2 px burr (wide bench)
    spill = 2 * int(np.ceil(margin / step_arc)) + 1
    edge_out = np.maximum(edge0, np.nan_to_num(prof.edge_out, nan=0.0)) if prof.edge_out is not None else edge0
    upper_w = np.maximum(maximum_filter1d(np.where(valid, np.maximum(edge_out, base), base), spill, mode=mode)
                         + 1.5 * blur + 1.0, upper)
    area = dev_int
    if clean.sum() > 10:
        excess = prof.share - np.median(prof.share[:, clean], axis=1)[:, None]
        area = dev_int + np.where(valid, _band_sum(prof.rr, excess, upper, upper_w), 0.0)
    out: list[Defect] = []
    for sign, kind in ((-1.0, "burr"), (1.0, "chip")):
        sd = sign * dev_s
        sf = sign * dev_f
        # teeth of one ragged defect join over dips that stay above a third of the
        # threshold: a clean rim between two defects comes back to within the noise
        for a, b in _merge_runs(true_runs((sf > thr_f) & valid, whole), sf, whole, 0.35 * thr_f):
            idx = np.arange(a, b) % n
            h_ref = float(np.median(sd[idx]))
            # walk out to half the run's height, sub-sample by linear interpolation
            lo, hi = a, b - 1
            while sd[(lo - 1) % n] > 0.5 * h_ref and valid[(lo - 1) % n] and b - lo < n:
                lo -= 1
            while sd[(hi + 1) % n] > 0.5 * h_ref and valid[(hi + 1) % n] and hi + 1 - a < n:
                hi += 1
            v_lo_in, v_lo_out = sd[lo % n], sd[(lo - 1) % n]
            v_hi_in, v_hi_out = sd[hi % n], sd[(hi + 1) % n]
            f_lo = (v_lo_in - 0.5 * h_ref) / max(v_lo_in - v_lo_out, 1e-9)
            f_hi = (v_hi_in - 0.5 * h_ref) / max(v_hi_in - v_hi_out, 1e-9)
            # where the run's own last ray is under half its height (a low shelf the
            # smoothed share found and the edges' walk did not), the interpolation runs
            # back into the run, by as much as the shelf is flat: a 0.30 mm burr's stop
            # came out 6 px before its start and the burr was lost (wide frame 4620099,
            # a 65 deg hatch). The run's end stands there; ``fit_end`` reads it
            start, stop = lo - min(max(f_lo, 0.0), 1.0), hi + min(max(f_hi, 0.0), 1.0)
            pad = int(np.ceil((3.0 * blur + 3.0) / step_arc))
            win = np.arange(int(np.floor(start)) - pad, int(np.ceil(stop)) + pad + 1)
            ok = valid[win % n]
            if ok.sum() < 6:
                continue
            s_arc = win[ok] * step_arc
            # the ends on the area-true profile: the edge's crossing sits off the middle of
            # the blurred step (``rim_crossing``), which shortens chips and lengthens burrs
            # by ~1.3 blur. A burr's end is a step in it blurred by the camera and the 1 px
            # smoothing: its height, read 1.2 blur inside, is the step's 80-90 %, and half
            # of that put each end ~0.3 px out (square-ended burrs 0.64 px long at the
            # median; the benches' ragged burrs 0.4-0.5 px: wide 4540000, 620000, station
            # 60000 -> -0.1 to -0.2 px, lengths in tolerance 183 / 196 -> 190 / 198). A chip's
            # ends are read as they were: its medians sat at -0.2 to +0.3 px already
            step_blur = smoothed_blur if kind == "burr" else None
            s1, u1 = fit_end(s_arc, sign * dev_int_s[win[ok] % n], start * step_arc, blur, rising=True,
                             step_blur=step_blur, noise=end_noise)
            s2, u2 = fit_end(s_arc, sign * dev_int_s[win[ok] % n], stop * step_arc, blur, rising=False,
                             step_blur=step_blur, noise=end_noise)
            length = s2 - s1
            if not length >= cfg.rim_min_length_px:
                continue
            # the mean height: the area-true deviation integrated over the defect and the
            # blur's spill along the rim
            inside = (s_arc >= s1 - 2.5 * blur) & (s_arc <= s2 + 2.5 * blur)
            prof_h = area if kind == "chip" else dev_int
            height = float(np.sum(sign * prof_h[win[ok] % n][inside]) * step_arc) / length
            floor = _chip_floor(prof, win[ok] % n, s_arc, s1, s2, base, edge_out, blur) if kind == "chip" else 1.0
            if floor < cfg.chip_min_floor:
                continue  # lit as a groove's bottom, not a broken face in shadow
            # the area counts a chip's floor at the hole's level; it may be lit
            height /= floor
            if height < cfg.rim_min_height_px:
                continue  # the area-true height decides; the crossing only found it
            # ... and it must stand out of the rim either side of it: where the wall's model
            # is off along an arc (a groove or blotch it misreads), the whole arc's edge moves
            # by 0.3-0.7 px, and noise on it crossed the 1 px bar as short false "burrs" (wide
            # bench seed 82000: 2 of 3 false defects per 100 clean frames; the same recall
            # above the limit there, on wide seed 85000 and station seed 60000)
            local = _flank_level(sign * prof_h, valid, whole, s1, s2, blur, step_arc)
            if height - local * float(inside.sum()) * step_arc / length / floor < cfg.rim_min_height_px:
                continue
            if kind == "chip" and _groove_run_on(img, wall_level, zone_others if marks is None else zone_others | marks,
                                                 hole, ((s1 + s2) / 2.0) / rad, length, height, angles_deg,
                                                 blur) > cfg.chip_groove_share:
                continue  # a deep groove running into the rim
            if kind == "chip" and _groove_along_rim(img, wall_level, zone_others if marks is None else zone_others | marks,
                                                    hole, s1 / rad, s2 / rad, height, angles_deg,
                                                    blur) > cfg.chip_groove_along_share:
                continue  # a deep groove grazing the rim
            partial = not ok.all()
            significance = height * np.sqrt(length) / noise
            if significance < cfg.min_significance:
                continue
            if kind == "burr":
                # a burr's height as reported: its rays' edges' mean depth between its ends.
                # The area-true height above (what finds it) counts the burr's metal at the
                # wall's level, but it is 0.9-1.15 of it, a share of -0.4 to 0.25 of the
                # wall-to-hole step at 40 % hole contrast, and the height scales with it; the
                # edge's crossing (0.75) moves with the burr's level by 0.25 blur at most,
                # and the baseline, fitted to the crossings, holds the crossing's own offset.
                # Dev frames 7200-7349 / fresh seed 95000: within tolerance 97.3 / 94.2 % ->
                # 99.1 / 100 %, median abs. error 0.46 / 0.49 -> 0.22 / 0.26 px, better at
                # every height, burrs lower than 1.5 blur included
                along = (s_arc >= s1) & (s_arc <= s2)
                edge_height = float(np.mean(sd[win[ok] % n][along])) if along.any() else 0.0
                if edge_height > 0.0:
                    height = edge_height
            # the length and place on the rim's own circle (the baseline's), not the hole's
            # fit: large rim defects pull that fit (``_RimCircle``)
            a1, a2 = circle.arc(s1 / step_arc), circle.arc(s2 / step_arc)
            th = (a1 + a2) / (2.0 * circle.radius)
            rc = circle.radius - height / 2.0 if kind == "burr" else circle.radius + height / 2.0
            u_len = float(np.hypot(u1, u2)) * (a2 - a1) / length
            length = a2 - a1
            # the noise over the defect, and its level: a chip's floor read or taken as the
            # hole's errs by ~10 %; a burr's level moves its edges' crossing by up to 0.25
            # blur (uniform: 0.15 blur). With the model term (0.6 px) that holds 97-98 % of
            # burrs' heights within 2u on the dev and fresh frames (10 % of the height, the
            # area-true height's term, held 98-100 % at a median u 30-45 % larger)
            level = 0.15 * blur if kind == "burr" else 0.1 * height
            u_h = float(np.hypot(noise * np.sqrt(2.5 * blur / max(length, 1.0)), level))
            out.append(Defect(kind, float(circle.x + rc * np.cos(th)), float(circle.y + rc * np.sin(th)),
                              float(length), float(height), confidence_of(significance, cfg.min_significance),
                              float(np.rad2deg(th) % 360.0), u_len, u_h, float(significance), partial, index))
    return out


def _flank_level(values: np.ndarray, valid: np.ndarray, whole: bool, s1: float, s2: float, blur: float,
                 step_arc: float) -> float:
    """The level of ``values`` (per ray, signed as the defect) on the rim either side of
    [s1, s2] (px of arc), past the blur's spill: the lower of the two flanks' medians,
    0 when it is below 0 or a flank is not read."""
    n = values.size
    gap = 2.5 * blur
    width = max(8.0, s2 - s1)
    levels = []
    for a, b in ((s1 - gap - width, s1 - gap), (s2 + gap, s2 + gap + width)):
        k = np.arange(int(np.floor(a / step_arc)), int(np.ceil(b / step_arc)) + 1)
        if not whole:
            k = k[(k >= 0) & (k < n)]
        k = k % n
        k = k[valid[k]]
        if k.size < 4:
            return 0.0
        levels.append(float(np.median(values[k])))
    return max(min(levels), 0.0)


def darkness_reader(img: np.ndarray, wall_level: np.ndarray, others: np.ndarray):
    """A function of points (..., 2) giving the wall's darkness 1 - I / W there (W the
    frame's level ``wall_level``, bilinear), NaN off the frame and in ``others``."""
    hh, ww = img.shape
    level = np.asarray(wall_level, np.float32)

    def darkness(pts: np.ndarray) -> np.ndarray:
        x = pts[..., 0].astype(np.float32)
        y = pts[..., 1].astype(np.float32)
        v = cv2.remap(img, x, y, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE).astype(np.float32)
        w = cv2.remap(level, x, y, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
        ix, iy = np.rint(x).astype(int), np.rint(y).astype(int)
        inside = (ix >= 0) & (iy >= 0) & (ix < ww) & (iy < hh)
        inside[inside] = ~others[iy[inside], ix[inside]]
        return np.where(inside, 1.0 - v / np.maximum(w, 1.0), np.nan)

    return darkness


def _hole_darkness(darkness, centre: np.ndarray, rad: float, theta: float) -> float | None:
    """The hole's own darkness towards angle ``theta`` (rad): the median over 11 points
    across 10 px at 0.6 of its radius; None where fewer than 3 are read or it is under
    0.05 (no hole to compare a mark with)."""
    radial = np.array([np.cos(theta), np.sin(theta)])
    inner = centre + 0.6 * rad * radial + np.linspace(-5.0, 5.0, 11)[:, None] * np.array([-radial[1], radial[0]])
    d = darkness(inner[None])
    if np.isfinite(d).sum() < 3:
        return None
    v = float(np.nanmedian(d))
    return v if v > 0.05 else None


def _groove_along_rim(img: np.ndarray, wall_level: np.ndarray, others: np.ndarray, hole, theta1: float,
                      theta2: float, height: float, angles_deg, blur: float) -> float:
    """How dark the wall stays beyond both ends of a chip found between angles
    ``theta1`` and ``theta2`` (rad) of ``hole``'s rim, ``height`` px deep, along lines
    of the hatch's directions through the notch and just outside it, as a share of the
    hole's darkness (both 1 - I / W, as ``_groove_run_on``): a deep groove that grazes
    the rim (runs nearly along its tangent) darkens the wall along an arc just outside
    it and moves the edge out there as a notch does, but leaves the rim at under 0.2 of
    the radial direction, where ``_groove_run_on`` does not look; its darkness runs on
    along its line past both the notch's ends, where a chip's wall comes back.

    Lines 1 px of arc apart across the notch, at 0.5, 0.75 and 1 of its depth out from
    the rim and 1.5 blur beyond its depth (where the edge is read, the groove's skirt
    and the hole's blurred step together reach the edge's crossing: a groove that makes
    a shallow notch has its middle outside it), are followed both ways along each
    direction from where each leaves the notch (its ends' angles or its depth), 3 blur
    + 2 px on, over 24 px; points nearer the hole's centre than its radius plus that
    clearance (the rim's blurred step, the hole beyond it), off the frame or in
    ``others`` are not read, nor a line with fewer than 8 points left. Each line's
    median darkness, each way's upper quartile over a depth's lines; the lower of the
    two ways, the greatest over the depths and directions. A direction that either way
    does not read (one that runs into the hole, the radial test's) counts 0, as does a
    hole under 0.05 dark."""
    centre = np.array([hole.x_px, hole.y_px])
    rad = hole.diameter_px / 2.0
    mid = 0.5 * (theta1 + theta2)
    half = 0.5 * (theta2 - theta1)
    darkness = darkness_reader(img, wall_level, others)
    hole_dark = _hole_darkness(darkness, centre, rad, mid)
    if hole_dark is None:
        return 0.0
    depth = max(height, 1.0)
    th = np.linspace(theta1, theta2, max(3, int(np.ceil(2.0 * half * rad)) + 1))
    ray = np.stack([np.cos(th), np.sin(th)], axis=1)
    clear = 3.0 * blur + 2.0
    walk = np.arange(0.0, 2.0 * rad + 2.0 * depth + 2.0 + 1.5 * blur, 0.5)  # long enough to cross the notch
    read = np.arange(0.0, 24.0, 1.0)
    best = 0.0
    for out_px in (0.5 * depth, 0.75 * depth, depth, depth + 1.5 * blur):
        q = centre + (rad + out_px) * ray  # (lines, 2)
        for a in angles_deg:
            u = np.array([np.cos(np.deg2rad(a)), np.sin(np.deg2rad(a))])
            ways = []
            for sgn in (1.0, -1.0):
                d = q[:, None, :] + sgn * walk[None, :, None] * u - centre
                r = np.hypot(d[..., 0], d[..., 1])
                dth = (np.arctan2(d[..., 1], d[..., 0]) - mid + np.pi) % (2.0 * np.pi) - np.pi
                outside = (np.abs(dth) > half) | (r > rad + max(depth, out_px)) | (r < rad - 1.0)
                left = walk[np.argmax(outside, axis=1)]  # where each line leaves the notch
                pts = q[:, None, :] + sgn * (left[:, None] + clear + read[None, :])[..., None] * u
                dd = pts - centre
                v = np.where(np.hypot(dd[..., 0], dd[..., 1]) >= rad + clear, darkness(pts), np.nan)
                ok = np.isfinite(v).sum(axis=1) >= 8
                if not ok.any():
                    break
                ways.append(float(np.percentile(np.nanmedian(v[ok], axis=1), 75.0)))
            if len(ways) == 2:
                best = max(best, min(ways))
    return best / hole_dark


def _groove_run_on(img: np.ndarray, wall_level: np.ndarray, others: np.ndarray, hole, theta: float, length: float,
                   height: float, angles_deg, blur: float) -> float:
    """How dark the wall stays beyond a chip found at angle ``theta`` (rad) of ``hole``'s
    rim (``length`` px of arc, ``height`` px deep), along the hatch's directions, as a
    share of the hole's own darkness (both 1 - I / W, W the frame's level ``wall_level``).

    For each groove direction that leaves the rim outwards (at least 0.2 of it radial),
    lines in that direction from the notch's mouth on the rim (1 px apart, across its
    length and 1 px beyond each end) are read over 24 px, starting where each leaves the
    notch (through its depth or its side) and then 3 blur + 2 px further radially (clear
    of the blurred step), at least 6 px along; each line's median darkness, and the upper
    quartile of the lines' (the darkest direction's).  A chip's notch ends and the wall
    beyond is the wall (a groove's depth, ~0.05 of the hole's darkness at the median); a
    deep groove that runs into the rim carries its darkness on over the notch it makes,
    which is as wide as the groove (0.48-0.77). The darkest line alone (until session 40)
    read a deep groove that merely crosses a true chip's arc and runs on from it: on a 30
    %-contrast hole its darkness is the hole's, and 2 of 37 chips above the limit were
    lost (wide envelope, 22 deg hatch, seed 78000: darkest line 0.65 and 0.88, upper
    quartile 0.23 and 0.19).
    Points off the frame or in another hole's zone (``others``) are not read, nor a line
    with fewer than 8 points left.  0 when no direction leaves the rim outwards."""
    radial = np.array([np.cos(theta), np.sin(theta)])
    tang = np.array([-radial[1], radial[0]])
    centre = np.array([hole.x_px, hole.y_px])
    rad = hole.diameter_px / 2.0
    darkness = darkness_reader(img, wall_level, others)
    hole_dark = _hole_darkness(darkness, centre, rad, theta)
    if hole_dark is None:
        return 0.0
    # lines through the notch's mouth on the rim, 1 px apart across its length and 1 px
    # beyond each end, in each groove direction, each read from where it leaves the
    # notch (its depth, or its side): read from the notch's outer end along the radius
    # (until session 50), the lines missed a deep groove that meets the rim obliquely,
    # or two that meet at it in a V, whose darkness the notch's depth carries out along
    # the radius or the bisector, away from the grooves' own lines (wide bench: 0.08-0.18
    # mm "chips", run-on shares 0.11-0.24)
    half = length / 2.0 + 1.0
    offsets = np.arange(-half, half + 1e-9, 1.0)
    rim = centre + rad * radial
    best = 0.0
    for a in angles_deg:
        u = np.array([np.cos(np.deg2rad(a)), np.sin(np.deg2rad(a))])
        if u @ radial < 0:
            u = -u
        ur, ut = float(u @ radial), float(u @ tang)
        if ur < 0.2:
            continue
        leave = np.full(offsets.size, max(height, 0.0) / ur)
        if abs(ut) > 1e-6:
            leave = np.minimum(leave, (half - np.sign(ut) * offsets) / abs(ut))
        t0 = max(6.0, (3.0 * blur + 2.0) / ur)
        t = leave[:, None] + t0 + np.arange(0.0, 24.0, 1.0)[None, :]
        d = darkness(rim + offsets[:, None, None] * tang + t[:, :, None] * u)
        read = np.isfinite(d).sum(axis=1) >= 8
        if read.any():
            best = max(best, float(np.percentile(np.nanmedian(d[read], axis=1), 75.0)))
    return best / hole_dark


def _chip_floor(prof: _RimProfile, rays: np.ndarray, s_arc: np.ndarray, s1: float, s2: float, base: np.ndarray,
                edge_out: np.ndarray, blur: float) -> float:
    """A chip's floor as a share of the wall-to-hole step (1: as dark as the hole), by
    which its area-true height is divided. Its broken face slopes into the hole in
    shadow, but not always at the hole's level: a floor lit to 0.7 of the step read a
    6.5 px notch as 3.2 px (dev frames). Read just beyond the rim's own blurred step (1.5
    blur to 1.5 blur + 1.5 px out) on the rays where the notch is deep enough to hold a
    plateau there (its outer end, ``edge_out``, 3 blur + 1.5 px out) and whose share of
    the notch along the rim, under the blur, is at least 0.9 (a 6 px chip under 1.9 px of
    blur covers 0.85 of its middle ray: its floor read 0.68 for 0.95), divided by that
    share; the median over them. 1 where fewer than 3 rays hold one: a shallow or short
    notch's floor and size trade off under the blur, and only their product is read.

    Not for burrs: a burr's torn metal is 0.9-1.15 of the wall's level, which at a hole
    of 40 % contrast is a share of -0.4 to 0.25, but a burr is ragged (its height varies
    by 30 % over 1.5 px along the rim), its rays' share falls off across any window
    inside its rim, and the same reading over-corrected deep burrs by 30-40 % (dev
    frames). A burr's height is read from its rays' edges instead (``rim_defects``)."""
    along = float(np.sqrt(blur**2 + 1.0 / 6.0))  # the camera's blur and the rays' sampling
    cover = ndtr((s_arc - s1) / along) - ndtr((s_arc - s2) / along)
    vals = []
    for i, c in zip(rays[cover >= 0.9], cover[cover >= 0.9]):
        if not prof.valid[i] or not edge_out[i] - base[i] >= 3.0 * blur + 1.5:
            continue
        sel = (prof.rr >= base[i] + 1.5 * blur) & (prof.rr <= base[i] + 1.5 * blur + 1.5)
        if sel.any():
            vals.append(float(np.mean(prof.share[sel, i])) / c)
    if len(vals) < 3:
        return 1.0
    return float(np.clip(np.median(vals), 0.3, 1.3))


def _merge_runs(runs: list[tuple[int, int]], sd: np.ndarray, wrap: bool, floor: float = 0.0) -> list[tuple[int, int]]:
    """Join runs of one sign whose gap stays above ``floor`` throughout: a ragged burr's
    height dips below the threshold between its teeth without the rim coming back, two
    defects side by side are apart where it does (dev frames: two chips 15 px apart
    read as one 39 px chip with a floor of zero)."""
    if len(runs) < 2:
        return runs
    n = sd.size
    runs = sorted(runs)
    out = [runs[0]]
    for a, b in runs[1:]:
        pa, pb = out[-1]
        gap = np.arange(pb, a) % n
        if gap.size == 0 or (sd[gap] > floor).all():
            out[-1] = (pa, b)
        else:
            out.append((a, b))
    if wrap and len(out) > 1:
        pa, pb = out[-1]
        a, b = out[0]
        gap = np.arange(pb, a + n) % n
        if pb - n < a and (gap.size == 0 or (sd[gap] > floor).all()):
            out[0] = (pa, b + n)
            out.pop()
    return out
