"""Pores: a blurred-ellipse fit for the floor's contrast, the outline from the
darkening's angular density, the greatest Feret diameter and the extent across it.

Part of ``station.vision.defects`` (its docstring tells the method).
"""

from __future__ import annotations

import functools

import cv2
import numpy as np
from scipy.special import ive, ndtr

from station.vision.defects.config import DefectConfig
from station.vision.defects.common import feret, gauss_newton, weighted_pca
from station.vision.defects.wall import Patch
from station.vision.defects.scratches import BLUR_PRIOR_PX


def _ellipse_model(p, xx, yy):
    """A blurred dark ellipse: an erf edge at the ellipse's radius in each direction,
    capped by the peak darkness of a blurred disc of the same area (1 - exp(-R^2/2s^2)),
    which small pores never reach; plus an offset."""
    cx, cy, a, b, th, c, s, off = p
    dx, dy = xx - cx, yy - cy
    ct, st = np.cos(th), np.sin(th)
    xr, yr = dx * ct + dy * st, -dx * st + dy * ct
    rho = np.hypot(xr, yr)
    psi = np.arctan2(yr, xr)
    r_e = a * b / np.sqrt((b * np.cos(psi)) ** 2 + (a * np.sin(psi)) ** 2 + 1e-12)
    peak = 1.0 - np.exp(-(a * b) / (2.0 * s * s))
    return off + c * np.minimum(ndtr((r_e - rho) / s), peak)


def _fit_contrast(r, xx, yy, use, cx, cy, cov, mass,
                  blur_held: float | None = None) -> tuple[float, float, float, float, np.ndarray]:
    """The pore floor's contrast c (relative darkness), the blur s (px), c's standard
    deviation, the fitted ellipse's aspect (major / minor axis, the blur taken out) and
    its parameters (``_ellipse_model``),
    from a robust fit of a blurred ellipse started from the darkening's moments; the
    blur free in 0.5-3.5 px, or held within 2 % of ``blur_held``."""
    evals, evecs = np.linalg.eigh(cov)
    evals = np.maximum(evals, 0.25)
    # a uniform ellipse of semi-axes a, b has variances a^2/4 and b^2/4 along them
    a0, b0 = 2.0 * np.sqrt(evals[1]), 2.0 * np.sqrt(evals[0])
    th0 = float(np.arctan2(evecs[1, 1], evecs[0, 1]))
    c0 = float(np.clip(mass / (np.pi * a0 * b0), 0.05, 0.95))
    p0 = np.array([cx, cy, a0, b0, th0, c0, 1.3 if blur_held is None else blur_held, 0.0])
    b_lo, b_hi = (0.5, 3.5) if blur_held is None else (0.98 * blur_held, 1.02 * blur_held)
    lo = np.array([cx - 5, cy - 5, 0.5, 0.5, th0 - np.pi, 0.01, b_lo, -0.2])
    hi = np.array([cx + 5, cy + 5, 4 * a0 + 5, 4 * a0 + 5, th0 + np.pi, 1.2, b_hi, 0.2])
    x, y, v = xx[use], yy[use], r[use]
    if v.size > 2500:  # every k-th pixel: the fit's speed, the contrast is just as well fixed
        k = int(np.ceil(v.size / 2500))
        x, y, v = x[::k], y[::k], v[::k]
    p0 = np.clip(p0, lo, hi)
    fit = gauss_newton(lambda p: _ellipse_model(p, x, y), p0, v, lo, hi)
    c, s = float(fit.x[5]), float(fit.x[6])
    c_sd = float(np.sqrt(max(fit.cov[5, 5], 0.0))) if np.isfinite(fit.cov[5, 5]) else c
    aspect = float(max(fit.x[2], fit.x[3]) / max(min(fit.x[2], fit.x[3]), 0.25))
    return c, s, c_sd, aspect, fit.x


#: a pore's outline is read to the order whose harmonic the blur still keeps this much of
#: (``_harmonic_attenuation``), at most ``OUTLINE_MAX_ORDER``, and only while the noise
#: that the harmonic's division by it carries into the radius stays under
#: ``OUTLINE_RIPPLE_NOISE_PX``: beyond, the grain's noise outweighs the shape. Faint
#: 12 px pores on 8 % grooves (noise 0.24-0.38 px at harmonic 4) read 0.9 px too wide
#: on average with harmonic 4 let in on the attenuation alone
OUTLINE_MIN_ATTENUATION = 0.5
OUTLINE_MAX_ORDER = 8
OUTLINE_RIPPLE_NOISE_PX = 0.25


@functools.lru_cache(maxsize=4096)
def _harmonic_attenuation_cached(radius_q: int, blur_q: int, kmax: int) -> tuple[float, ...]:
    rho, sigma = radius_q / 20.0, blur_q / 100.0
    s = np.linspace(max(rho - 8.0 * sigma, 0.0), rho + 8.0 * sigma, 801)
    g = (s / sigma**2) * np.exp(-((s - rho) ** 2) / (2.0 * sigma**2))
    return tuple(float(np.trapezoid(g * ive(k, s * rho / sigma**2), s)) for k in range(1, kmax + 1))


def _harmonic_attenuation(radius: float, blur: float, kmax: int = OUTLINE_MAX_ORDER) -> np.ndarray:
    """How much a Gaussian blur ``blur`` (px) keeps of the angular harmonics k = 1..kmax,
    about a centre, of darkening at ``radius`` (px) from it. A point's darkening at
    radius rho, spread by the blur sigma and read as harmonic k round the centre, keeps
    h_k = integral over s of s / sigma^2 exp(-(s^2 + rho^2) / 2 sigma^2) I_k(s rho / sigma^2) ds
    (the Rice law with the weight I_k for I_0; about exp(-k^2 sigma^2 / 2 rho^2) when
    rho >> sigma).
    A mark's outline is r(theta); a ripple of it at the rim is read attenuated by h_k at
    the rim's radius. Cached on radius to 0.05 px and blur to 0.01 px."""
    rq = int(round(max(radius, 0.5) * 20.0))
    bq = int(round(max(blur, 0.3) * 100.0))
    return np.array(_harmonic_attenuation_cached(rq, bq, int(kmax)))


def _outline(r, xx, yy, omega, cx, cy, mass: float, c: float, blur: float, with_gain: bool = False,
             deconvolve: bool = True, noise: float | None = None):
    """A dark mark's outline, radius against angle (360 angles over -pi..pi), from the
    darkening ``r`` over ``omega``: its angular density round the centroid is
    c r(theta)^2 / 2 (the area a direction holds), whatever the blur; as a Fourier series
    of the pixels' angles (no binning). The blur spreads the darkening across
    directions, which keeps only h_k of the outline's harmonic k (``_harmonic_attenuation``
    at the mark's equivalent radius): each harmonic read is divided by its h_k, up to the
    order where h_k falls under ``OUTLINE_MIN_ATTENUATION`` or, given the ``noise`` of a
    coefficient, where the division would carry more than ``OUTLINE_RIPPLE_NOISE_PX`` of
    it into the radius. Read as it was blurred (the first version, to the order
    k sigma / R < 1 and not divided), the outline was smoothed: on 445 pores of 5-50 px
    (station envelope, no hole) the greatest Feret diameter read 0.61 px short and the
    width 0.34 px short on average, with their area right to 0.01 px of radius; divided,
    -0.07 and -0.08 px (wide envelope, 359 pores: -0.39 / -0.25 -> +0.07 / -0.06 px,
    the length's spread 1.10 -> 0.96 px).

    With ``with_gain``, also the sum of 1 / h_k^2 over the harmonics kept, which is what
    the grain's noise in the outline grows with. ``deconvolve`` False: the outline as
    blurred, to the order k sigma / R < 1 (2-8; the edge-blur test's, which asks how far
    the mark departs from the blurred ellipse it was fitted with)."""
    dx, dy = xx[omega] - cx, yy[omega] - cy
    phi = np.arctan2(dy, dx)
    mv = r[omega]
    r_eq = np.sqrt(max(mass / c, 1.0) / np.pi)
    if deconvolve:
        att = _harmonic_attenuation(r_eq, blur)
        ok = att >= OUTLINE_MIN_ATTENUATION
        if noise is not None:
            # a harmonic's coefficients each carry the noise of a sum over omega; divided
            # by h_k, that is this much of the outline's radius (px)
            ok &= noise * np.sqrt(2.0) / (att * np.pi * c * r_eq) <= OUTLINE_RIPPLE_NOISE_PX
        order = int(max(2, np.sum(np.cumprod(ok))))
        att = att[:order]
    else:
        order = int(np.clip(np.floor(r_eq / max(blur, 0.7)), 2, OUTLINE_MAX_ORDER))
        att = np.ones(order)
    ks = np.arange(1, order + 1)
    cos_k, sin_k = np.cos(ks[:, None] * phi[None, :]), np.sin(ks[:, None] * phi[None, :])
    a_k, b_k = (cos_k @ mv) / att, (sin_k @ mv) / att
    th = np.linspace(-np.pi, np.pi, 360, endpoint=False)
    harmonics = a_k @ np.cos(ks[:, None] * th[None, :]) + b_k @ np.sin(ks[:, None] * th[None, :])
    density = (mass + 2.0 * harmonics) / (2 * np.pi)
    rr = np.sqrt(np.clip(2.0 * density / c, 0.0, None))
    return (th, rr, float(np.sum(1.0 / att**2))) if with_gain else (th, rr)


def _outline_roughness(th: np.ndarray, rr: np.ndarray) -> float:
    """The RMS of an outline's radius about its ellipse (px): how far the outline departs
    from what the blurred-ellipse model can follow. An ellipse centred on the origin has
    1 / r^2 = A + B cos 2 theta + C sin 2 theta exactly; the first harmonic is let in for
    a centroid that is not the ellipse's centre (least squares on 1 / r^2)."""
    ok = rr > 0.5
    if ok.sum() < 12:
        return 0.0
    t = th[ok]
    basis = np.column_stack([np.ones_like(t), np.cos(2 * t), np.sin(2 * t), np.cos(t), np.sin(t)])
    coef, *_ = np.linalg.lstsq(basis, 1.0 / rr[ok] ** 2, rcond=None)
    q = np.column_stack([np.ones_like(th), np.cos(2 * th), np.sin(2 * th), np.cos(th), np.sin(th)]) @ coef
    fitted = 1.0 / np.sqrt(np.maximum(q, 1e-12))
    return float(np.sqrt(np.mean((rr - fitted) ** 2)))


def measure_pore(patch: Patch, region: np.ndarray, cfg: DefectConfig, allow_scratch: bool = True,
                 blur_hint: float | None = None, beside: np.ndarray | None = None):
    """A pore: centroid, outline from the darkening in 32 sectors, greatest Feret
    diameter and the extent across it, with standard uncertainties (px, before the
    config's factor), the significance and the floor's contrast.

    ``blur_hint``: the camera's blur, if known (the frame's holes, a calibration). The
    tests (contrast, edge blur, elongation) read the fit with the blur free; the outline
    reads a fit with the blur held at the camera's, since a pore's rim is a sharp break
    in the wall's plane. A small pore's contrast, size and edge blur trade off: with the
    blur free, 11-13 px pores of 46 % contrast on 4 % grain and 8 % grooves fitted a
    blur of 2.3-2.7 px (1.4 and 0.8 rendered) and their contrast ran to its bound, 1.2,
    which read them 40 % small (fresh bench seeds 80000, 95000). Without a known blur,
    a fit whose contrast passes 1 (a floor darker than black) is done again with the
    blur held at the station's prior (``BLUR_PRIOR_PX``).

    ``beside``: other marks beside the pore (the rest of its candidate's region,
    ``_peak_part``), left out of its integration and its fit with 2 px round them."""
    r = patch.residual.astype(np.float64)
    h, w = r.shape
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float64)
    off = patch.zone
    if beside is not None and beside.any():
        off = off | (cv2.dilate(beside.astype(np.uint8), np.ones((5, 5), np.uint8)).astype(bool) & ~region)
    # the blurred edge reaches ~2.5 blur beyond the outline: integrate 5 px past the region
    omega = (cv2.dilate(region.astype(np.uint8), np.ones((11, 11), np.uint8)).astype(bool) & ~off) | region
    wts = np.where(omega, r, 0.0)
    mass = float(wts.sum())
    if mass <= 0:
        return None
    significance = mass / (5.0 * patch.noise_box5 * np.sqrt(omega.sum()))
    mean_darkness = float(r[region].mean())
    if significance < cfg.min_significance or mean_darkness < cfg.min_mean_darkness:
        return None  # before the fit, which costs most of a candidate's time
    pos = np.clip(wts, 0.0, None)
    cx, cy, _, cov = weighted_pca(xx, yy, pos)
    fit_area = cv2.dilate(omega.astype(np.uint8), np.ones((9, 9), np.uint8)).astype(bool) & ~off
    c, blur, c_sd, aspect, fitted = _fit_contrast(r, xx, yy, fit_area, cx, cy, cov, mass)
    if allow_scratch and aspect >= cfg.scratch_elongation:
        return dict(scratch=True)  # long and thin once the blur is taken out: a short scratch
    if c < cfg.min_pore_contrast:
        return dict(faint=True, contrast=c)  # no pore (``examine._accept``); the level may have followed it
    blur_limit = cfg.edge_blur_limit(blur_hint)
    if blur > blur_limit:
        # the blurred ellipse takes a ragged outline's departure from an ellipse for blur
        # (a radial scatter rho widens the mean edge to sqrt(s^2 + rho^2)): what the
        # outline's own harmonics beyond the ellipse's say of it comes off first. A soft
        # shading of the wall has a smooth outline and keeps its blur
        th, rr = _outline(r, xx, yy, omega, cx, cy, mass, c, blur, deconvolve=False)
        rough = _outline_roughness(th, rr)
        if np.sqrt(max(blur * blur - rough * rough, 0.0)) > blur_limit:
            return None
    held = blur_hint
    if held is None and c > 1.0:
        # no blur known and a floor darker than black: the fit traded size for blur; the
        # station's blur, as the scratches' prior has it, is the better guess
        held = BLUR_PRIOR_PX[0]
    if held is not None:
        c, blur, c_sd, _, fitted = _fit_contrast(r, xx, yy, fit_area, cx, cy, cov, mass,
                                                 blur_held=float(np.clip(held, 0.5, 3.5)))
    contrast = c  # the contrast the tests read (``examine._accept``): the mark against the wall as modelled
    # a pore takes the wall's place, grooves and all: its floor is one level, and the
    # grooves' model subtracted over it took their darkness off it, light stripes along
    # the lines through it (a 0.45 x 0.32 mm pore with deep grooves running into it read
    # 0.25 for its 0.35 floor, 9 % long and 21 % wide: wide bench 4540016). For
    # its size the grooves go back under the fitted ellipse, blurred as the pore is, and
    # it is fitted again at that blur. Not for the tests: a crossing of grooves read as
    # a mark then holds the lines' whole darkness, and is a dark, even blot
    q = np.array(fitted, float)
    q[5], q[7] = 1.0, 0.0
    cut = r + patch.grooves * _ellipse_model(q, xx, yy)
    wts = np.where(omega, cut, 0.0)
    if float(wts.sum()) > 0:
        r, mass = cut, float(wts.sum())
        cx, cy, _, cov = weighted_pca(xx, yy, np.clip(wts, 0.0, None))
        c, blur, c_sd, _, _ = _fit_contrast(r, xx, yy, fit_area, cx, cy, cov, mass,
                                            blur_held=float(np.clip(blur, 0.5, 3.5)))
    # noise of a sum over n px: the 5x5 box mean's spread x 25 per 25 px (correlated
    # grain); each coefficient sums the pixels with weights of RMS 1/sqrt(2); r^2 = 2 D / c
    u_coef = 5.0 * patch.noise_box5 * np.sqrt(omega.sum() / 2.0)
    th, rr, gain = _outline(r, xx, yy, omega, cx, cy, mass, c, blur, with_gain=True,
                            noise=u_coef)
    r_eq = np.sqrt(max(mass / c, 1.0) / np.pi)
    length, direction, width = feret(rr * np.cos(th), rr * np.sin(th))
    u_density = u_coef * np.sqrt(2.0 * gain) / np.pi
    u_r = u_density / (c * max(r_eq, 1.0))
    u_scale = c_sd / (2.0 * c)  # the outline scales as c^-1/2
    u_len = float(np.sqrt(2.0 * u_r**2 + (length * u_scale) ** 2))
    u_wid = float(np.sqrt(2.0 * u_r**2 + (width * u_scale) ** 2))
    return dict(x=cx, y=cy, length=length, width=width, angle=direction, u_length=u_len, u_width=u_wid,
                significance=float(significance), contrast=contrast, blur=blur, mean_darkness=mean_darkness)
