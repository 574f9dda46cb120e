"""Photometric refinement of a whole hole: a blurred-disc model fitted to the pixels.

Why: the ray edges (``edges.py``) each see the wall texture right next to the rim, and
their errors (~0.1 px per ray) are correlated over 1-2 px of rim, so a rim of 60-300
px averages only 30-150 independent errors.  Fitting one intensity model of the whole
hole to every pixel of an annulus around its rim uses all the pixels at once, with a
robust loss that lets the pixels of a honing groove crossing the annulus lose their
weight, and the hole's featureless inside pins the dark level.

Model, at distance rho from the centre (cx, cy) and angle theta:

    I = W(theta, rho) (1 - u) + H(theta) u,   u = P(|X| < R(theta)), X ~ N((rho, 0), s^2 I)

u is a disc of radius R blurred by an isotropic Gaussian of variance s^2 (camera blur
plus the pixel's area, 1/12 px^2 in every direction); |X| is Rice-distributed, and
for rho R / s^2 >> 1 (always here: R >= 10 px, s <= 2.1 px)
u ~ Phi((R - m) / v), |X| as a Gaussian about its median m with its spread v, both to
second order in s / rho (``disc_edge``; round 16: the first-order Phi((R - sqrt(rho^2 +
s^2)) / s) read the blur 0.015 px low on small holes at heavy blur), within 0.0002 px of
R and 0.0015 px of s when both are fitted to the exact non-central chi-square cdf
(``test_photometric_disc_model_matches_the_exact_blurred_disc``).  R(theta) = R0 +
a cos 2theta + b sin 2theta (an oval hole, to first order); W is the wall: a Fourier
series in theta (per-sector level, vignetting, blotches), the honing grooves read from
the wall ring beyond the rim, and the smooth wall's radial slope from the same ring (a
free slope in the annulus and a tilt of H are options, off by default); H the far side
of the hole, a level times the frame illumination's curvature over the hole (its tilt
is flat-fielded away first).  The wall is cut by the hole before the camera blurs it, which
adds s_cam^2 / s phi(t) dW/drho to the model (the blur's product rule).  The angles
are measured from the starting centre and stay fixed, so the wall and hole bases are
fixed functions of the pixel position and only rho depends on the centre.

The pixels: the annulus and the hole's whole inside (which pins H); the grooves' profiles
come from the hole's wide neighbourhood when the caller gives them (``grooves.py``), else
from the ring alone.

Fit: Gauss-Newton with the analytic Jacobian, each pixel weighted by its expected variance
and by Huber weights (IRLS) on the residuals against a robust (MAD) scale, a handful of
iterations from the ray fit's circle.
Uncertainties: the white-noise standard deviations (``r_sd``, ...) and a kernel estimate
of the least-squares sandwich from the residuals' own spatial correlation (``r_u``, ...,
``_hac_sd``): the grain blurred by the camera is correlated noise.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import cv2
import numpy as np
from numba import njit
from scipy.special import ndtr

from station.vision.fit import gradient_1d, median, solve_small

#: 1 / sqrt(2 pi)
_INV_SQRT_2PI = 0.3989422804014327
#: MAD -> standard deviation for Gaussian data
_MAD_TO_SIGMA = 1.4826


@dataclass(frozen=True)
class PhotometricConfig:
    #: annulus half-width around the rim: k_sigma * s + pad_px on each side (2.0 instead
    #: of 2.5: ~a fifth fewer pixels; dev frames 3000-3199, 296 holes: diameter median
    #: 0.0202 vs 0.0191 px, within its sampling noise, 90th percentile 0.056 vs 0.064,
    #: worst 0.18 vs 0.20)
    k_sigma: float = 2.0
    pad_px: float = 1.0
    #: Fourier order of the wall level in angle
    wall_order: int = 4
    #: Huber threshold in robust standard deviations of the residuals: 5 keeps gross
    #: outliers (dust, a glint) from pulling the fit and is least squares otherwise;
    #: the grain is Gaussian and the grooves are modelled; the gain over 1.345 is small
    #: (dev frames 3000-3199 / 9000-9199, with the cut term and an 18 px ring, diameter
    #: |error| px: median 0.0166 / 0.0186 at 1.345 against 0.0162 / 0.0180 at 5, mean
    #: 0.0248 / 0.0265 against 0.0250 / 0.0259, 90th percentile 0.054 / 0.058 against
    #: 0.055 / 0.054)
    huber_k: float = 5.0
    #: Gauss-Newton steps: from the ray fit's circle 3 do as well as 6 (dev frames
    #: 3000-3199: the same diameter median, 0.0191 px at k_sigma 2.5, 0.0202 at 2.0)
    iterations: int = 3
    #: fit the blur (else keep the one measured on the rays)
    fit_blur: bool = True
    oval: bool = True
    #: radial slope of the wall: Fourier order (-1: none)
    wall_slope_order: int = -1
    #: Fourier order of the hole's level (0: constant)
    hole_order: int = 0
    #: the hole's level follows the frame illumination's curvature (``illumination_curv``,
    #: the quadratic of ``illumination.py`` about the hole, relative): vignetting darkens
    #: the far side towards the rim as it does the wall, and a constant level reads that as
    #: more hole (a 100 px hole at 50 % vignetting on 640 x 480: +0.024 px -> +0.005 px).
    #: The wall's curvature stays the ring's (its reflectance varies, the far side's does
    #: not).  Bench seeds 1000 / 20000 (session 41): diameter z^2 -0.012 +/- 0.005 /
    #: -0.002 +/- 0.004, mean z +0.131 -> +0.108 / +0.016 -> -0.002, the centre unchanged
    hole_illumination_curvature: bool = True
    #: honing cross-hatch: groove directions (deg from the x axis, y down); None: no
    #: groove model
    groove_angles_deg: tuple[float, ...] | None = (30.0, -30.0)
    #: wall ring (px beyond the annulus' transition zone) the groove profiles come from:
    #: more pixels per profile bin against a groove's depth changing along its length
    #: (dev 3000-3199 / 9000-9199, diameter median: 12 px 0.0175 / 0.0183, 15 px
    #: 0.0163 / 0.0183, 18 px 0.0162 / 0.0180, 24 px 0.0162 / 0.0182)
    groove_margin_px: float = 18.0
    groove_bin_px: float = 0.5
    #: backfitting sweeps between the two families' profiles
    groove_backfit: int = 3
    #: 2: a profile per family on each side of the hole (along the grooves); 1: one
    groove_sides: int = 1
    #: pseudo-counts that shrink a sparse bin towards 0
    groove_pseudo_count: float = 2.0
    #: weight each pixel by its expected variance: the hole's side carries sensor noise
    #: only, the wall's the grain as well, mixed by the texture's share (1 - u)^2 (the
    #: robust scales of the residuals inside and outside); on since round 13, with the
    #: hole's inside read (``interior_px``) and a blur shared by the frame
    texture_weighting: bool = True
    #: model that the grooves are cut by the hole before the blur: the image is
    #: B[G (1 - c)], not B[G] (1 - B[c]); to first order in the blur they differ by
    #: s_cam^2 grad B[G] . grad B[1 - c] = s_cam^2 / s phi(t) dG/drho, read from the groove
    #: profiles' derivative.  Dev frames (median / mean |error|, px): 3000-3199 0.0186 /
    #: 0.0271 -> 0.0175 / 0.0262, 9000-9199 0.0211 / 0.0277 -> 0.0183 / 0.0270; with the
    #: term's sign flipped 0.0205 / 0.0301, at 0.5x or 2x its size worse than at 1x
    groove_cut_term: bool = True
    #: the smooth wall's radial slope at the rim (blotches, vignetting): B[W (1 - c)]
    #: for a wall W = W0 + g (rho - R) is W (1 - u) + s_cam^2 g phi(t) / s, a shift of
    #: the edge by s_cam^2 g / (W - H) (0.006 px for 0.25 DN/px at s = 1.2 px and 60 DN
    #: of contrast).  The annulus cannot tell g from R (a free slope costs more than it
    #: gains: docs/vision.md), so g comes from the groove ring, once its grooves are
    #: removed: a level and a slope, each a Fourier series in angle (the slope of this
    #: order; -1: none) ...
    ring_slope_order: int = 1
    #: ... shrunk towards 0 by this factor (``ring_slope_poly`` 0, the Fourier slope: 0.5
    #: is its best): the ring's slope is the mean over 18 px further out, not the rim's,
    #: and a regression of the renderer's true slope at the
    #: rim on the ring's (dev frames 3000-3099, 140 holes) has a coefficient of 0.57.
    #: Six dev sets (3000, 5000, 9000, 11000, 13000, 15000, 200 frames each, 1,748 whole
    #: holes), diameter |error| px median / mean / 90th percentile: no slope 0.0173 /
    #: 0.0250 / 0.056; shrink 1: 0.0168 / 0.0233 / 0.052; 0.75: 0.0164 / 0.0230 / 0.052;
    #: 0.5: 0.0162 / 0.0232 / 0.052; 0.4: 0.0164 / 0.0234 / 0.052
    ring_slope_shrink: float = 1.0
    #: > 0 (the default since round 15): the ring's smooth wall as its level's Fourier series
    #: in angle plus a 2-D polynomial of this degree in x and y, and the slope at each
    #: annulus pixel the polynomial's radial derivative there, not a shrunk mean over the
    #: ring.  A blotch's curvature makes the slope grow with the distance from the centre:
    #: the ring's mean slope, taken 18 px further out, overstates the rim's (hence the
    #: shrink of 0.5 above), while the polynomial carries it in to the rim, shrink 1.
    #: Dev seeds 3000 / 5000, 400 frames each (611 / 601 holes), RMS z of the diameter
    #: against the grooved bound: Fourier slope, shrink 0.5: 1.130 / 1.134; degree 2:
    #: 1.102 / 1.112 (centre 1.107 / 1.062 -> 1.100 / 1.066; diameters beyond 3 sigma 1.80 /
    #: 0.83 % -> 1.47 / 0.83 %).  On 3000-3199: degree 2 with shrink 0.75: 1.094; degree 3:
    #: 1.087 for the diameter but 1.139 for the centre; degree 1 (a plane: no radial slope
    #: on average) 1.187, as no slope at all
    ring_slope_poly: int = 2
    #: the uncertainties (``r_u``, ``cx_u``, ``cy_u``) from the residuals' own spatial
    #: correlation (a kernel estimate of the sandwich: each pixel's influence on the
    #: parameter times its residual, summed over pairs of pixels up to this many
    #: correlation lengths apart, with Bartlett weights); 0: none
    hac_lengths: float = 2.5
    #: sectors of the annulus judged by their residuals' chi-square against the whole
    #: annulus's robust scale (0: none); a sector whose mean squared residual exceeds
    #: ``sector_chi2`` times the scale's square gets its weights divided by the excess
    #: pixels weighted by 1 / (1 + (share x the groove model's own size there / the
    #: residual scale)^2): the groove model's error taken as this share of what it
    #: subtracts (its level and its cut term), so that pixels where much is modelled
    #: count less (0: equal weights)
    groove_error_share: float = 0.0
    #: with the frame's groove profiles (``grooves.frame_grooves``) given: the ring gives
    #: only each family's depth at the hole, an amplitude of this order in x and y (0:
    #: a constant, 1: linear), not a profile of its own
    groove_frame_amp_order: int = 1
    #: ... and then, if > 0, a profile of the ring's own on what the frame's leaves,
    #: shrunk towards 0 (towards the frame's) by these pseudo-counts per bin (0: none) ...
    groove_frame_local_pseudo: float = 20.0
    #: ... one per side of the hole along the grooves (2) or one for both (1).  A groove
    #: fades along its length, so its two crossings of the rim differ by what the frame's
    #: amplitude (linear over the ring) leaves.  Round 19 (with ``MeasureConfig.
    #: groove_window_px`` 250): sides 1 with 10 pseudo-counts -> sides 2 with 20 (half the
    #: pixels per bin), dev seeds 3000 / 5000, diameter z^2 -0.023 / -0.021 +/- 0.014, centre
    #: -0.025 / -0.017 +/- 0.009 on average over the same holes; 2 sides with 5 pseudo-counts
    #: gave nothing and moved the diameters' mean up by 0.05 sigma
    groove_frame_local_sides: int = 2
    #: the hole's inside read this far (px) inside the annulus (0: the annulus only; None:
    #: down to the centre)
    interior_px: float | None = None
    sectors: int = 0
    sector_chi2: float = 1.5
    #: Gauss-Newton steps with the noise's covariance (``gls.py``: the wall's grain as
    #: correlated noise) after the weighted ones; 0: weighted least squares only
    gls_steps: int = 0
    #: the pixel's square area in the edge's profile beyond its variance (``pixel_box_term``:
    #: the fourth cumulant of the square projected on the radius).  Without it the model
    #: misfits the camera's rim (optics, then the pixel's square) by an odd ripple, up to
    #: 1.6e-4 of the step at 1 px of blur, that a weighted fit hardly sees but the
    #: grain-aware step, whose covariance is lopsided (grain on the wall side only), reads
    #: as a diameter 0.001 px short (from the true parameters, on a noise-free render;
    #: docs/vision-history.md, round 17)
    pixel_box: bool = True


@dataclass(frozen=True)
class PhotometricFit:
    cx: float
    cy: float
    r: float  # mean radius R0 (px)
    blur_px: float  # s: camera blur with the pixel's area
    contrast_dn: float  # median wall level - hole level over the annulus
    rms_dn: float  # robust residual scale
    n_pixels: int
    iterations: int
    #: False when the model ran away from the rays' circle (radius or centre more than
    #: 2 px off, or not finite): the pixels around this rim are not a blurred disc.  The
    #: other fields then hold the start, not a fit
    converged: bool = True
    #: standard deviation of R0 by white-noise theory (the robust residual scale times the
    #: inverse normal matrix of the last step); the texture makes the real scatter larger
    #: (``MeasureConfig.uncertainty_factor``).  NaN when not converged
    r_sd: float = float("nan")
    #: the same for the centre's x and y (px)
    cx_sd: float = float("nan")
    cy_sd: float = float("nan")
    #: standard deviations of R0, cx and cy from the residuals' spatial correlation
    #: (``PhotometricConfig.hac_lengths``: the grain, blurred by the camera, and what is
    #: left of the grooves are correlated noise, which the white-noise figures miss)
    r_u: float = float("nan")
    cx_u: float = float("nan")
    cy_u: float = float("nan")
    #: RMS (DN) of the honing-groove field the model subtracts over the annulus' wall
    #: side: how much texture the fit had to model at the rim
    groove_rms_dn: float = float("nan")
    #: standard deviation of the blur s by white-noise theory (NaN when the blur was
    #: held fixed or the fit did not converge): what a frame-shared blur weighs it by
    #: when ``blur_u`` is missing
    blur_sd: float = float("nan")
    #: the same from the residuals' spatial correlation (``hac_lengths``), with the blur
    #: fitted by the weighted steps only: what a frame-shared blur weighs it by
    #: (``measure._frame_blur``); NaN otherwise
    blur_u: float = float("nan")
    #: the last step was weighed by the noise's covariance (``PhotometricConfig.gls_steps``):
    #: the uncertainties are its inverse normal matrix, scaled by the chi-square
    gls: bool = False
    #: with the blur held fixed (``fit_blur`` False: the frame's shared blur), how R0, cx
    #: and cy move per px of that blur (-M^-1 m_s of the last step's normal matrix M and
    #: the blur's column m_s): an error e of the held blur moves them by e times these,
    #: which r_u, cx_u and cy_u (the blur taken as exact) leave out.  NaN otherwise
    r_ds: float = float("nan")
    cx_ds: float = float("nan")
    cy_ds: float = float("nan")


def disc_edge(rho: np.ndarray, s: float) -> tuple[np.ndarray, np.ndarray, tuple[np.ndarray, np.ndarray],
                                                  tuple[np.ndarray, np.ndarray]]:
    """The blurred disc's edge at distance ``rho`` (Gaussian blur of std ``s``): the
    share of a disc of radius R there is Phi((R - m) / v), with

        m = sqrt(Q) + s^4 / (6 Q^1.5),   v = s sqrt(1 - s^2 / (2 Q)),   Q = rho^2 + s^2,

    the distance |X| of X ~ N((rho, 0), s^2 I) (Rice-distributed) as a Gaussian about its
    median with its standard deviation, to second order in s / rho: the median is below
    the mean sqrt(Q) by the skew of the chi-square term, and the spread is narrower than s.
    Returns m, v and their derivatives in rho and in s: (m, v, (dm/drho, dv/drho),
    (dm/ds, dv/ds)).  Against the exact non-central chi-square cdf, a fit of R and s
    together is within 0.0002 px of R and 0.0015 px of s down to a 6 px radius at
    s = 1.5 px; the first-order model Phi((R - sqrt(Q)) / s) (before round 16) reads s
    0.015 px low on an 11 px radius at s = 1.9 px
    (``test_photometric_disc_model_matches_the_exact_blurred_disc``)."""
    q2 = rho * rho + s * s
    q = np.sqrt(q2)
    s2 = s * s
    k = s2 * s2 / (6.0 * q2 * q)
    m = q + k
    w = np.sqrt(1.0 - s2 / (2.0 * q2))  # >= sqrt(1/2): q2 >= s2
    v = s * w
    dm_drho = rho / q - 3.0 * k * rho / q2
    dv_drho = s * s2 * rho / (2.0 * w * q2 * q2)
    dm_ds = s / q + 4.0 * k / s - 3.0 * k * s / q2
    dv_ds = w - s * (s / q2 - s * s2 / (q2 * q2)) / (2.0 * w)
    return m, v, (dm_drho, dv_drho), (dm_ds, dv_ds)


def disc_fraction(rho: np.ndarray, radius: float | np.ndarray, s: float) -> np.ndarray:
    """Share of a disc of ``radius`` blurred by a Gaussian of std ``s`` at distance ``rho``
    (``disc_edge``)."""
    m, v, _, _ = disc_edge(rho, s)
    return ndtr((radius - m) / v)


def pixel_box_term(t: np.ndarray, v: np.ndarray, cos_t: np.ndarray, sin_t: np.ndarray) -> np.ndarray:
    """What a pixel's square area adds to the blurred disc's share Phi(t), t = (R - m) / v,
    beyond the 1/12 px^2 of variance that ``v`` already holds: the square projected on the
    radius (direction ``cos_t``, ``sin_t``) is the sum of two uniform variables of widths
    |cos|, |sin|, whose fourth cumulant is -(cos^4 + sin^4) / 120 px^4 (a Gaussian's is 0).
    To first order in it (Edgeworth) the share gains kappa_4 / 24 d^4 Phi / drho^4 =
    kappa_4 / 24 (3 t - t^3) phi(t) / v^4: an odd ripple about the edge, up to 1.6e-4 of
    the step at v = 1 px.  With it, the misfit to the exact disc (x) Gaussian (x) pixel is 15
    times smaller than without it at 1 px of blur, 12 times at 0.8 px
    (``test_the_pixels_square_is_in_the_disc_model``)."""
    k4 = -(cos_t**4 + sin_t**4) / 120.0
    return k4 / (24.0 * v**4) * (3.0 * t - t**3) * (_INV_SQRT_2PI * np.exp(-0.5 * t * t))


#: rows per block in the normal equations: OpenBLAS multi-threads a product of
#: m * n * k >= 65536 * 4 multiply-adds (its GEMM_MULTITHREAD_THRESHOLD); below that it
#: stays on the calling core, which is what the one-core budget assumes
_BLAS_SINGLE_THREAD_MACS = 65536 * 4


def _normal(a: np.ndarray, wa: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """wa^T a and wa^T b, summed over row blocks small enough for one core."""
    k = a.shape[1]
    block = max(_BLAS_SINGLE_THREAD_MACS // (k * k) - 1, 64)
    m, v = np.zeros((k, k)), np.zeros(k)
    for i in range(0, len(a), block):
        wt = wa[i : i + block].T
        m += wt @ a[i : i + block]
        v += wt @ b[i : i + block]
    return m, v


def _frame_groove_field(
    dx: np.ndarray, dy: np.ndarray, v: np.ndarray, wall: np.ndarray, targets: np.ndarray, cfg: PhotometricConfig,
    fg, cx: float, cy: float, x0: int, y0: int, roi_w: int,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``_groove_field`` with the families' shapes from the hole's wide neighbourhood
    (``fg``: a ``grooves.FrameGrooves``): the wall ring gives each family's amplitude (a
    polynomial of ``groove_frame_amp_order`` in x and y) beside a quadratic smooth level,
    least squares.  Only the ring's and the targets' pixels are computed."""
    use = wall | targets
    idx = np.flatnonzero(use)
    dxu, dyu = dx[idx], dy[idx]
    iy, ix = np.divmod(idx, roi_w)
    level = fg.level_at(ix + x0, iy + y0).astype(np.float64)
    vals, ders = fg.values(dxu + cx, dyu + cy)
    sc = max(float(np.max(np.abs(dxu))), float(np.max(np.abs(dyu))), 1.0)
    xs, ys = dxu / sc, dyu / sc
    one = np.ones(idx.size)
    amp = [one] + ([xs, ys] if cfg.groove_frame_amp_order >= 1 else [])
    if cfg.groove_frame_amp_order >= 2:
        amp += [xs * xs, xs * ys, ys * ys]
    gcols = np.stack([level * p * a for p in vals for a in amp], axis=1)
    on_wall = wall[idx]
    aw = np.concatenate([np.stack([one, xs, ys, xs * xs, xs * ys, ys * ys], axis=1), gcols], axis=1)[on_wall]
    m, rhs = _normal(aw, aw, v[idx][on_wall])
    try:
        coef = np.linalg.solve(m + 1e-9 * np.eye(m.shape[0]), rhs)
    except np.linalg.LinAlgError:
        return np.zeros(int(targets.sum())), np.zeros(int(targets.sum())), np.zeros(int(wall.sum()))
    gc = coef[6:]
    field = gcols @ gc
    na = len(amp)
    rho = np.maximum(np.hypot(dxu, dyu), 1e-9)
    d_rho = np.zeros(idx.size)
    for f, a in enumerate(fg.angles_rad):
        ampl = sum(gc[f * na + k] * amp[k] for k in range(na))
        d_rho += level * ders[f] * ampl * (-np.sin(a) * dxu + np.cos(a) * dyu) / rho
    on_target = targets[idx]
    return field[on_target], d_rho[on_target], field[on_wall]


def _groove_field(
    dx: np.ndarray, dy: np.ndarray, v: np.ndarray, wall: np.ndarray, targets: np.ndarray, cfg: PhotometricConfig
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The honing grooves' intensity (DN, about the smooth wall) at the ``targets`` pixels,
    its radial derivative there, and the grooves at the ``wall`` pixels (their bins' values).

    A groove is straight and keeps its profile along its length, so each family is a
    1-D profile P_k across its direction; the wall pixels (``wall``) around the hole
    give P_1 and P_2 by backfitting bin means (0.5 px bins, shrunk towards 0 where
    few pixels fall) after a quadratic smooth level is removed.  The rim's own pixels
    never enter: the profiles there are read from the same lines further out.
    """
    angles = np.deg2rad(np.asarray(cfg.groove_angles_deg, dtype=np.float64))
    return _groove_kernel(dx[wall], dy[wall], v[wall], dx[targets], dy[targets], angles, float(cfg.groove_bin_px),
                          cfg.groove_backfit, cfg.groove_sides, float(cfg.groove_pseudo_count))


@njit(cache=True, nogil=True)
def _groove_kernel(xw, yw, vw, xt, yt, angles, step, n_backfit=3, sides=1, pseudo=2.0):
    """``_groove_field``'s work on the wall pixels (xw, yw, vw) and the targets (xt, yt).
    (Compiled: about twenty numpy calls on a few thousand pixels each.)"""
    nw, nt, nf = xw.size, xt.size, angles.size
    scale = 1.0
    for i in range(nw):
        scale = max(scale, abs(xw[i]), abs(yw[i]))
    # the smooth level: a quadratic in x and y, least squares
    m = np.zeros((6, 6))
    rhs = np.zeros(6)
    basis = np.empty(6)
    for i in range(nw):
        x, y = xw[i] / scale, yw[i] / scale
        basis[0], basis[1], basis[2], basis[3], basis[4], basis[5] = 1.0, x, y, x * x, x * y, y * y
        for a in range(6):
            rhs[a] += basis[a] * vw[i]
            for b in range(a, 6):
                m[a, b] += basis[a] * basis[b]
    for a in range(6):
        m[a, a] += 1e-9
        for b in range(a):
            m[a, b] = m[b, a]
    coef, _ = solve_small(m, rhs)
    resid = np.empty(nw)
    for i in range(nw):
        x, y = xw[i] / scale, yw[i] / scale
        resid[i] = vw[i] - (coef[0] + coef[1] * x + coef[2] * y + coef[3] * x * x + coef[4] * x * y + coef[5] * y * y)
    # each family's 1-D profile across its direction, by backfitting bin means (two
    # pseudo-counts shrink sparse bins towards 0); with ``sides`` 2, one profile for
    # each side of the line through the centre along the grooves (a groove fades along
    # its length: the rim's two crossings of one groove differ)
    u_max = 1.5 * scale
    nb1 = int(2 * u_max / step) + 2
    nb = nb1 * sides
    idx = np.empty((nf, nw), dtype=np.int64)
    counts = np.full((nf, nb), pseudo)
    for f in range(nf):
        sn, cs = np.sin(angles[f]), np.cos(angles[f])
        for i in range(nw):
            j = int((-sn * xw[i] + cs * yw[i] + u_max) / step)  # truncation, as numpy's astype
            j = min(max(j, 0), nb1 - 1)
            if sides > 1 and cs * xw[i] + sn * yw[i] > 0:
                j += nb1
            idx[f, i] = j
            counts[f, j] += 1.0
    prof = np.zeros((nf, nb))
    sums = np.empty(nb)
    for _ in range(n_backfit if nf > 1 else 1):
        for f in range(nf):
            sums[:] = 0.0
            for i in range(nw):
                other = 0.0
                for g in range(nf):
                    if g != f:
                        other += prof[g, idx[g, i]]
                sums[idx[f, i]] += resid[i] - other
            for j in range(nb):
                prof[f, j] = sums[j] / counts[f, j]
    # read back at the targets: the field and its derivative along the radius
    centres = np.arange(nb1).astype(np.float64)
    field = np.zeros(nt)
    d_rho = np.zeros(nt)
    for f in range(nf):
        sn, cs = np.sin(angles[f]), np.cos(angles[f])
        ut = np.empty(nt)
        for i in range(nt):
            ut[i] = (-sn * xt[i] + cs * yt[i] + u_max) / step - 0.5
        for side in range(sides):
            p = prof[f, side * nb1:(side + 1) * nb1]
            slope = gradient_1d(p) / step
            fv = np.interp(ut, centres, p)
            ds = np.interp(ut, centres, slope)
            for i in range(nt):
                if sides > 1 and (cs * xt[i] + sn * yt[i] > 0) != (side == 1):
                    continue
                field[i] += fv[i]
                rho = max(np.sqrt(xt[i] * xt[i] + yt[i] * yt[i]), 1e-9)
                d_rho[i] += ds[i] * (-sn * xt[i] + cs * yt[i]) / rho
    g_wall = np.zeros(nw)
    for f in range(nf):
        for i in range(nw):
            g_wall[i] += prof[f, idx[f, i]]
    return field, d_rho, g_wall


def _fourier(c1: np.ndarray, s1: np.ndarray, order: int) -> list[np.ndarray]:
    """1, cos theta, sin theta, ..., cos(order theta), sin(order theta) from cos and sin
    of theta (the angle-addition recurrence)."""
    out, ck, sk = [np.ones_like(c1)], np.ones_like(c1), np.zeros_like(c1)
    for _ in range(order):
        ck, sk = ck * c1 - sk * s1, sk * c1 + ck * s1
        out += [ck, sk]
    return out


def _ring_fit(dx: np.ndarray, dy: np.ndarray, v: np.ndarray, r: float,
              cfg: PhotometricConfig) -> tuple[np.ndarray, np.ndarray, int]:
    """The wall ring's smooth level, least squares on the ring pixels ``dx``, ``dy`` with
    their grooves removed (``v``): level (Fourier order ``wall_order``) + (rho - r) slope
    (order ``ring_slope_order``).  Returns the coefficients, the design matrix and how
    many of its columns are the level's."""
    rho = np.maximum(np.hypot(dx, dy), 1e-9)
    level = _fourier(dx / rho, dy / rho, max(cfg.wall_order, cfg.ring_slope_order))
    a = np.stack(level + [b * (rho - r) for b in level[: 2 * max(cfg.ring_slope_order, 0) + 1]], axis=1)
    m, rhs = _normal(a, a, v)
    return np.linalg.solve(m + 1e-9 * np.eye(a.shape[1]), rhs), a, len(level)


def _ring_slope(dx: np.ndarray, dy: np.ndarray, v: np.ndarray, r: float, basis: list[np.ndarray],
                cfg: PhotometricConfig, adx: np.ndarray | None = None, ady: np.ndarray | None = None) -> np.ndarray:
    """The smooth wall's radial slope (DN/px) at the annulus' pixels (``basis``: their
    ``_fourier`` terms, at least to ``ring_slope_order``), from the ring's fit
    (``_ring_fit``); with ``ring_slope_poly`` > 0 from a 2-D polynomial instead
    (``_ring_poly_slope``: ``adx``, ``ady`` are the annulus pixels' offsets)."""
    if cfg.ring_slope_poly > 0 and adx is not None:
        return _ring_poly_slope(dx, dy, v, cfg, adx, ady)
    coef, _, n_level = _ring_fit(dx, dy, v, r, cfg)
    return sum(c * b for c, b in zip(coef[n_level:], basis))


def _ring_poly_slope(dx: np.ndarray, dy: np.ndarray, v: np.ndarray, cfg: PhotometricConfig, adx: np.ndarray,
                     ady: np.ndarray) -> np.ndarray:
    """The smooth wall's radial slope (DN/px) at the annulus' pixels ``adx``, ``ady``: the
    ring (``dx``, ``dy``, its grooves removed: ``v``) fitted by its level's Fourier series
    in angle plus a 2-D polynomial of degree ``ring_slope_poly`` in x and y (least
    squares), whose gradient, dotted with the radial direction, is the slope."""
    rho = np.maximum(np.hypot(dx, dy), 1e-9)
    scale = float(rho.max())  # x and y in -1..1: a well-conditioned normal matrix
    x, y = dx / scale, dy / scale
    terms = [(i, n - i) for n in range(1, cfg.ring_slope_poly + 1) for i in range(n + 1)]
    level = _fourier(dx / rho, dy / rho, cfg.wall_order)
    a = np.stack(level + [x**i * y**j for i, j in terms], axis=1)
    m, rhs = _normal(a, a, v)
    coef = np.linalg.solve(m + 1e-9 * np.eye(a.shape[1]), rhs)[len(level):]
    ax, ay = adx / scale, ady / scale
    arho = np.maximum(np.hypot(adx, ady), 1e-9)
    gx = sum(c * i * ax ** (i - 1) * ay**j for c, (i, j) in zip(coef, terms) if i > 0) / scale
    gy = sum(c * j * ax**i * ay ** (j - 1) for c, (i, j) in zip(coef, terms) if j > 0) / scale
    return (gx * adx + gy * ady) / arho


def refine_hole(
    image: np.ndarray,
    cx: float,
    cy: float,
    r: float,
    blur_px: float,
    cfg: PhotometricConfig = PhotometricConfig(),
    illumination_grad: tuple[float, float] | None = None,
    frame_grooves=None,
    illumination_curv: tuple[float, float, float] | None = None,
    roi_blur_px: float | None = None,
    cache: dict | None = None,
) -> PhotometricFit | None:
    """Fit the blurred-disc model around a whole hole's rim; None when it cannot run (too
    few wall pixels, a singular system), ``converged=False`` when the model runs away.

    ``illumination_grad``: the frame illumination's relative gradient (per px) at the
    hole (``illumination.Illumination.relative_gradient``); the hole's pixels are divided
    by 1 + g . (x - (cx, cy)) first, so that the model sees reflectance only.
    ``illumination_curv``: its second-order part there (``Illumination.
    relative_curvature``: qxx, qxy, qyy per px^2), which the hole's level follows
    (``PhotometricConfig.hole_illumination_curvature``).
    ``frame_grooves``: the grooves' profiles over the hole's wide neighbourhood
    (``grooves.FrameGrooves``; None: from the ring alone).  ``roi_blur_px``: the blur
    that sizes the annulus and the ring (default ``blur_px``); ``cache``: a dict that
    keeps the groove model between two fits of one hole from the same start and
    ``roi_blur_px`` (the second with the frame's blur held fixed)."""
    h, w = image.shape
    s = float(np.clip(blur_px, 0.4, 4.0))
    s_roi = float(np.clip(roi_blur_px, 0.4, 4.0)) if roi_blur_px is not None else s
    half = cfg.k_sigma * s_roi + cfg.pad_px
    r_in = 0.0 if cfg.interior_px is None else max(r - half - cfg.interior_px, 0.0)
    r_out = r + half
    r_clear = r + 2.5 * s_roi + 1.0  # beyond it the wall is free of the rim's blur
    grooves = bool(cfg.groove_angles_deg)
    r_roi = max(r_out, r_clear + cfg.groove_margin_px) if grooves else r_out
    x0, x1 = max(int(np.floor(cx - r_roi)), 0), min(int(np.ceil(cx + r_roi)) + 1, w)
    y0, y1 = max(int(np.floor(cy - r_roi)), 0), min(int(np.ceil(cy + r_roi)) + 1, h)
    if x1 - x0 < 3 or y1 - y0 < 3:
        return None
    xx = np.arange(x0, x1, dtype=np.float64) - cx
    yy = np.arange(y0, y1, dtype=np.float64) - cy
    dxa = np.broadcast_to(xx[None, :], (y1 - y0, x1 - x0)).ravel()
    dya = np.broadcast_to(yy[:, None], (y1 - y0, x1 - x0)).ravel()
    d2 = dxa * dxa + dya * dya
    va = image[y0:y1, x0:x1].ravel().astype(np.float64)
    if illumination_grad is not None:
        va = va / (1.0 + illumination_grad[0] * dxa + illumination_grad[1] * dya)
    sel = (d2 >= r_in * r_in) & (d2 <= r_out * r_out)
    roi_shape = (y1 - y0, x1 - x0)
    groove = 0.0
    if grooves:
        wall_px = (d2 > r_clear * r_clear) & (d2 <= r_roi * r_roi)
        if wall_px.sum() < 50:
            return None
        if cache is not None and "groove" in cache:
            groove, groove_drho, g_wall = cache["groove"]
        else:
            # the grooves matter where the wall is: the annulus, not the hole's inside
            near = sel & (d2 >= max(r - half, 0.0) ** 2)
            if frame_grooves is not None:
                gn, dn, g_wall = _frame_groove_field(dxa, dya, va, wall_px, near, cfg, frame_grooves, cx, cy,
                                                     x0, y0, x1 - x0)
                if cfg.groove_frame_local_pseudo > 0:
                    va_left = va.copy()
                    va_left[wall_px] -= g_wall
                    g2, d2_, w2 = _groove_field(dxa, dya, va_left, wall_px, near,
                                                replace(cfg, groove_pseudo_count=cfg.groove_frame_local_pseudo,
                                                        groove_sides=cfg.groove_frame_local_sides))
                    gn, dn, g_wall = gn + g2, dn + d2_, g_wall + w2
            else:
                gn, dn, g_wall = _groove_field(dxa, dya, va, wall_px, near, cfg)
            # back on the fit's pixels (0 inside)
            groove, groove_drho = np.zeros(int(sel.sum())), np.zeros(int(sel.sum()))
            on = near[sel]
            groove[on], groove_drho[on] = gn, dn
            if cache is not None:
                cache["groove"] = (groove, groove_drho, g_wall)
    dx, dy, v = dxa[sel], dya[sel], va[sel]
    n = v.size
    rho0 = np.sqrt(d2[sel])
    c1, s1 = dx / np.maximum(rho0, 1e-9), dy / np.maximum(rho0, 1e-9)
    # Fourier basis in the (fixed) starting angle
    K = cfg.wall_order
    fb = _fourier(c1, s1, max(K, 2, cfg.ring_slope_order))
    if grooves and cfg.ring_slope_order >= 0 and cfg.ring_slope_shrink > 0:
        if cache is not None and "slope" in cache:
            g = cache["slope"]
        else:
            g = cfg.ring_slope_shrink * _ring_slope(dxa[wall_px], dya[wall_px], va[wall_px] - g_wall, r,
                                                    fb[: 2 * cfg.ring_slope_order + 1], cfg, dx, dy)
            if cache is not None:
                cache["slope"] = g
        groove = groove + g * (rho0 - r)
        groove_drho = groove_drho + g
    cos_k, sin_k = [fb[0]] + fb[1::2], [np.zeros(n)] + fb[2::2]
    wall_cols = [cos_k[0]] + [b for k in range(1, K + 1) for b in (cos_k[k], sin_k[k])]
    t_rad = (rho0 - r) / half  # radial coordinate over the annulus, -1..1
    if cfg.wall_slope_order >= 0:
        wall_cols += [t_rad] + [t_rad * b for k in range(1, cfg.wall_slope_order + 1) for b in (cos_k[k], sin_k[k])]
    hole_cols = [cos_k[0]] + [b for k in range(1, cfg.hole_order + 1) for b in (cos_k[k], sin_k[k])]
    bw = np.stack(wall_cols, axis=1)
    bh = np.stack(hole_cols, axis=1)
    if cfg.hole_illumination_curvature and illumination_curv is not None:
        qxx, qxy, qyy = illumination_curv
        bh = bh * (1.0 + qxx * dx * dx + qxy * dx * dy + qyy * dy * dy)[:, None]
    nw = bw.shape[1]
    c2, s2 = cos_k[2], sin_k[2]

    # parameters: centre offset (ox, oy), R0, oval (a, b), s; wall and hole coefficients
    ox = oy = 0.0
    r0, a2, b2 = float(r), 0.0, 0.0
    lin = None
    scale = None
    prior = np.ones(n)
    it = 0
    gls_op = None
    weighted_left, gls_left = cfg.iterations, cfg.gls_steps
    while weighted_left > 0 or gls_left > 0:
        it += 1
        use_gls = weighted_left == 0
        if use_gls:
            gls_left -= 1
        else:
            weighted_left -= 1
        ex, ey = dx - ox, dy - oy
        rho = np.sqrt(ex * ex + ey * ey)
        radius = r0 + a2 * c2 + b2 * s2 if cfg.oval else r0
        m_e, v_e, (dm_drho, dv_drho), (dm_ds, dv_ds) = disc_edge(rho, s)
        t = (radius - m_e) / v_e
        u = ndtr(t)
        if cfg.pixel_box:
            # the model's value only: the term's own derivatives are ~1e-4 of the edge's
            inv = 1.0 / np.maximum(rho, 1e-9)
            u = u + pixel_box_term(t, v_e, ex * inv, ey * inv)
        phi = _INV_SQRT_2PI * np.exp(-0.5 * t * t)
        lin_cols = np.concatenate([bw * (1 - u)[:, None], bh * u[:, None]], axis=1)
        if lin is None:
            # levels for the starting geometry (plain least squares)
            m, rhs = _normal(lin_cols, lin_cols, v - groove * (1 - u))
            lin = np.linalg.solve(m + 1e-9 * np.eye(lin_cols.shape[1]), rhs)
        wall = bw @ lin[:nw] + groove
        hole = bh @ lin[nw:]
        res = v - (wall + (hole - wall) * u)
        cut = 0.0
        if grooves and cfg.groove_cut_term:
            # the wall (grooves, slope) is cut by the hole before the blur: B[G (1 - c)]
            # differs from B[G] (1 - B[c]) by s_cam^2 grad B[G] . grad B[1 - c] to first
            # order, and grad B[1 - c] = phi(t) / s along the radius
            cut = (s * s - 1.0 / 12.0) / s * groove_drho
            res -= cut * phi
        if scale is None or it <= 2:
            if cfg.texture_weighting:
                inner, outer = u > 0.9, u < 0.1
                var_in = (_MAD_TO_SIGMA * median(np.abs(res[inner]))) ** 2 if inner.sum() > 20 else 1.0
                var_out = (_MAD_TO_SIGMA * median(np.abs(res[outer]))) ** 2 if outer.sum() > 20 else var_in
                var = max(var_in, 0.25) + max(var_out - var_in, 0.0) * (1 - u) ** 2
                prior = 1.0 / var
                scale = 1.0
            else:
                scale = max(_MAD_TO_SIGMA * median(np.abs(res - median(res))), 0.5)
        if grooves and cfg.groove_error_share > 0 and it <= 2:
            gdev = groove - median(groove[t_rad > 0]) if np.any(t_rad > 0) else groove
            model_sd = cfg.groove_error_share * np.hypot(gdev * (1 - u), cut * phi)
            prior = 1.0 / (1.0 + (model_sd / scale) ** 2)
        a = np.abs(res) * np.sqrt(prior) / (cfg.huber_k * scale)
        wts = prior * np.where(a <= 1.0, 1.0, 1.0 / np.maximum(a, 1e-12))
        if cfg.sectors > 0:
            if it == 1:
                sector = (np.floor((np.arctan2(s1, c1) + np.pi) / (2 * np.pi) * cfg.sectors).astype(np.int64)
                          % cfg.sectors)
                cnt = np.maximum(np.bincount(sector, minlength=cfg.sectors), 1)
            if it <= 2:
                chi2 = np.bincount(sector, res * res, minlength=cfg.sectors) / cnt / (scale * scale)
                sec_w = 1.0 / np.maximum(chi2 / cfg.sector_chi2, 1.0)
            wts = wts * sec_w[sector]
        dh = (hole - wall - cut * t) * phi  # d model / dt (phi' = -t phi)
        # d model / d parameter
        drho_t = -(dm_drho + t * dv_drho) / v_e  # dt/drho
        inv_rho = 1.0 / np.maximum(rho, 1e-9)
        cols = [
            dh * drho_t * (-ex * inv_rho),  # d/d ox
            dh * drho_t * (-ey * inv_rho),  # d/d oy
            dh / v_e,  # d/d R0
        ]
        if cfg.oval:
            cols += [dh / v_e * c2, dh / v_e * s2]
        if cfg.fit_blur:
            cols.append(-dh * (dm_ds + t * dv_ds) / v_e)  # dt/ds
        nl = len(cols)
        jac = np.concatenate([np.stack(cols, axis=1), lin_cols], axis=1)
        jw = jac * wts[:, None]
        # a blur held fixed (the frame's) joins the normal matrix, not the step: the
        # parameters' sensitivity to it (``PhotometricFit.r_ds``)
        jac_x = jac if cfg.fit_blur else np.concatenate([jac, (-dh * (dm_ds + t * dv_ds) / v_e)[:, None]], axis=1)
        try:
            if use_gls:
                if gls_op is None:
                    gls_op = _gls_operator(res, u, sel, roi_shape, s, r0, ox, oy, dxa, dya,
                                           va, wall_px if grooves else None, g_wall if grooves else None, cfg)
                if gls_op is None:
                    break
                m, rhs, gls_chi2 = _gls_normal(gls_op, jac_x, res, sel, roi_shape)
            else:
                m, rhs = _normal(jac_x, jw if cfg.fit_blur else jac_x * wts[:, None], res)
            if not cfg.fit_blur:
                m, rhs, m_blur = m[:-1, :-1], rhs[:-1], m[:-1, -1]
            step = np.linalg.solve(m, rhs)
        except np.linalg.LinAlgError:
            return None
        ox += step[0]
        oy += step[1]
        r0 += step[2]
        k = 3
        if cfg.oval:
            a2 += step[3]
            b2 += step[4]
            k = 5
        if cfg.fit_blur:
            s = float(np.clip(s + step[k], 0.3, 4.0))
        lin = lin + step[nl:]
        if max(abs(step[0]), abs(step[1]), abs(step[2])) < 1e-3 and it >= 2 and not use_gls:
            weighted_left = 0  # converged: on to the covariance-weighted steps, if any
    if not (np.isfinite(ox) and np.isfinite(oy) and np.isfinite(r0)) or abs(r0 - r) > 2.0 or np.hypot(ox, oy) > 2.0:
        return PhotometricFit(cx, cy, r, float(blur_px), float("nan"), float(scale), n, it, converged=False)
    contrast = median(bw @ lin[:nw] - bh @ lin[nw:])
    ds = np.full(3, np.nan)
    try:
        m_inv = np.linalg.inv(m)
        diag = np.diag(m_inv)
        var = diag[:3]
        var_s = float(diag[k]) if cfg.fit_blur else float("nan")
        if not cfg.fit_blur:
            ds = -(m_inv[:3] @ m_blur)  # d(cx, cy, R0) / d(blur held)
    except np.linalg.LinAlgError:
        var, var_s = np.full(3, np.nan), float("nan")
    # NaN (not a warning) where the inverse gives no positive variance
    sd = np.sqrt(np.where(var > 0, var, np.nan)) * float(scale)
    g_rms = float("nan")
    if grooves:
        gw = (groove if np.ndim(groove) else np.zeros(n))[t_rad > 0]
        if gw.size:
            g_rms = float(np.sqrt(np.mean(np.square(gw - np.mean(gw)))))
    hac = np.full(3, np.nan)
    if gls_op is not None:
        # the last step weighed by the noise's covariance: its inverse normal matrix is
        # the covariance of the estimate, scaled by the residuals' chi-square per degree
        # of freedom (C's size is read from the ring, whose leftovers of grooves and
        # blotches it takes for grain; the chi-square corrects its scale, not its shape)
        dof = max(n - m.shape[0], 1)
        sd = np.sqrt(np.where(var > 0, var, np.nan) * max(gls_chi2, 0.0) / dof)
        hac = sd.copy()
    blur_u = float("nan")
    if gls_op is None and cfg.hac_lengths > 0:
        hac_cols = (0, 1, 2, k) if cfg.fit_blur else (0, 1, 2)  # cx, cy, R0 and the blur
        hac_all = _hac_sd(m, jw, res, sel, roi_shape, s, cfg.hac_lengths, hac_cols)
        hac = hac_all[:3]
        if cfg.fit_blur:
            blur_u = float(hac_all[3])
    return PhotometricFit(cx + ox, cy + oy, r0, s, contrast, float(scale), n, it,
                          r_sd=float(sd[2]), cx_sd=float(sd[0]), cy_sd=float(sd[1]),
                          r_u=float(hac[2]), cx_u=float(hac[0]), cy_u=float(hac[1]), groove_rms_dn=g_rms,
                          blur_sd=float(np.sqrt(var_s)) * float(scale) if var_s > 0 else float("nan"),
                          blur_u=blur_u, gls=gls_op is not None,
                          r_ds=float(ds[2]), cx_ds=float(ds[0]), cy_ds=float(ds[1]))


def _gls_operator(res, u, sel, shape, s, r0, ox, oy, dxa, dya, va, wall_px, g_wall, cfg):
    """The hole's noise operator (``gls.NoiseOperator``) from the weighted fit's residuals
    (the hole's side) and the wall ring's, its grooves removed, about a smooth level."""
    from station.vision.gls import NoiseOperator, estimate_noise

    s_cam = float(np.sqrt(max(s * s - 1.0 / 12.0, 0.01)))
    if wall_px is None:
        return None
    ex, ey = dxa - ox, dya - oy
    rho_f = np.sqrt(ex * ex + ey * ey)
    # the ring's residuals about its smooth level (the fit the ring's slope comes from)
    vw = va[wall_px] - g_wall
    coef, a, _ = _ring_fit(ex[wall_px], ey[wall_px], vw, r0, cfg)
    grid = np.zeros(shape[0] * shape[1])
    grid[wall_px] = vw - a @ coef
    grid = grid.reshape(shape)
    sel_g = sel.reshape(shape)
    rho = rho_f.reshape(shape)
    # the wall's share of each pixel: the disc cut by the pixel's area only
    wall_share = 1.0 - ndtr((r0 - np.sqrt(rho * rho + 1.0 / 12.0)) / np.sqrt(1.0 / 12.0))
    inner = u > 0.9
    inner_var = (_MAD_TO_SIGMA * median(np.abs(res[inner]))) ** 2 if inner.sum() > 20 else 1.0
    wall_ok = wall_px.reshape(shape)
    noise = estimate_noise(grid, wall_ok, max(inner_var, 0.25), s_cam)
    if noise is None:
        return None
    return NoiseOperator(noise, sel_g, wall_share, s_cam)


def _gls_normal(op, jac, res, sel, shape):
    """J^T C^-1 J, J^T C^-1 r and r^T C^-1 r with C the hole's ``NoiseOperator``."""
    k = jac.shape[1]
    b = np.zeros((k + 1, shape[0] * shape[1]))
    b[:k, sel] = jac.T
    b[k, sel] = res
    y = op.solve(b.reshape(k + 1, *shape)).reshape(k + 1, -1)[:, sel].astype(np.float64)
    m = jac.T @ y[:k].T
    return 0.5 * (m + m.T), jac.T @ y[k], float(res @ y[k])


def _hac_sd(m: np.ndarray, jw: np.ndarray, res: np.ndarray, sel: np.ndarray, shape: tuple[int, int], s: float,
            lengths: float, cols: tuple[int, ...] = (0, 1, 2)) -> np.ndarray:
    """Standard deviations of the parameters ``cols`` (by default the first three: cx,
    cy, R0) by a kernel
    (Bartlett) estimate of the least-squares sandwich: with G the rows of m^-1 for
    them, pixel i's influence is e_i = G jw_i res_i and var = sum over pairs (i, j) of
    w(i - j) e_i e_j, w = (1 - |dx| / (L + 1)) (1 - |dy| / (L + 1)) for |dx|, |dy| <= L.
    L: ``lengths`` times the correlation length of blurred grain, sqrt(s^2 + 0.7^2) px.
    The Bartlett kernel is a box's autocorrelation over (L + 1)^2, so the double sum is
    the sum of squares of the influences' (L + 1) x (L + 1) box sums, over every
    placement of the box: positive by construction, one box filter per parameter."""
    nc = len(cols)
    try:
        g = np.linalg.solve(m, np.eye(m.shape[0])[:, list(cols)]).T  # (nc, p): m is symmetric
    except np.linalg.LinAlgError:
        return np.full(nc, np.nan)
    e = (jw @ g.T) * res[:, None]  # (n, nc)
    lag = int(np.ceil(lengths * np.sqrt(s * s + 0.49)))
    iy, ix = np.divmod(np.flatnonzero(sel), shape[1])
    if iy.size == 0:
        return np.full(nc, np.nan)
    iy, ix = iy - iy.min() + lag, ix - ix.min() + lag
    k = lag + 1
    grid = np.zeros((iy.max() + lag + 1, ix.max() + lag + 1, nc))  # the parameters as channels
    grid[iy, ix] = e
    box = cv2.boxFilter(grid, cv2.CV_64F, (k, k), normalize=False, borderType=cv2.BORDER_CONSTANT)
    out = np.einsum("ijc,ijc->c", box, box) / (k * k)
    return np.sqrt(np.where(out > 0, out, np.nan))
