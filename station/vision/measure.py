"""Find and measure the compensating holes of one frame with sub-pixel accuracy.

The pipeline (each stage in its own module):

1. ``detect``: coarse candidates on a 4x downsampled, background-normalised frame;
2. ``edges``: per candidate, a wide ray search, a robust circle (RANSAC + IRLS), then
   a narrow ray search around that circle from its centre for the final edge points,
   their widths, and the blur-curvature correction of the radius;
3. ``fit``: geometric circle fit with Tukey weights (optionally on edge points
   undistorted by a camera calibration), and a direct ellipse fit for ovality.

Pixel convention: the centre of pixel (0, 0) is at (0, 0), x right, y down.  With a
calibration, positions and diameters are in *ideal* (undistorted) pixels of the same
camera matrix, so that mm follow from one scale.
"""

from __future__ import annotations

import functools
from dataclasses import asdict, dataclass, replace
from typing import NamedTuple

import cv2
import numpy as np
from numba import njit
from scipy.special import chdtrc

from station.vision.calibration import CameraCalibration
from station.vision.detect import Candidate, DetectConfig, detect_candidates, for_scale
from station.vision.edges import KERNEL_RADIUS_PX, deblurred_radius, gradient, profile_width2, psf_variance, ray_edges
from station.vision.edges import SMOOTH_SIGMA_PX
from station.vision.fit import fit_ellipse_direct, gradient_1d, median, ransac_circle, robust_circle, taubin_circle
from station.vision.grooves import frame_grooves, frame_hatch, wall_level
from station.vision.illumination import Illumination, estimate_illumination
from station.vision.imageio import to_8bit, to_grey
from station.vision.photometric import PhotometricConfig, PhotometricFit, refine_hole


@dataclass(frozen=True)
class MeasureConfig:
    detect: DetectConfig = DetectConfig()
    #: half-width of the final ray window (px): holds the peak +/-1 px for edge widths
    #: up to sigma ~ 2.5 px (camera blur 2 px + pixel area + our 1 px smoothing)
    fine_window_px: float = 4.5
    min_valid_rays: int = 24
    min_inlier_fraction: float = 0.5
    max_rms_px: float = 1.0
    #: minimum share of the rim that must be measurable (a quarter: 90 deg of arc)
    min_coverage: float = 0.25
    #: below this a "hole" is a texture crossing: on rendered frames most texture
    #: candidates score <= 0.1 (not all: see min_relative_contrast), real whole holes
    #: >= 0.77 on the station envelope and >= 0.21 on the wide one (docs/vision.md)
    min_confidence: float = 0.15
    #: a whole hole with a photometric fit is judged by the better of the rays' scatter
    #: and its own diameter uncertainty (``diameter_u_px``) against this (px; the
    #: worst-case diameter bar): on heavy grooves the rays scatter by 0.3-0.5 px RMS
    #: around a rim the fit measures to 0.05-0.15 px (None: the rays' scatter only)
    confidence_u_ref_px: float | None = 0.15
    #: a hole must be this much darker than the wall just outside its rim ((wall -
    #: inside) / wall, medians of the pixels clear of the rim's blur).  A through-hole
    #: is dark: dev frames 3000-3199 and 9000-9199 (585 whole, 185 cut holes) measure
    #: >= 0.35 on the station envelope (40-85 % contrast) and >= 0.23 on the wide one
    #: (30-80 %); the crossing of deep honing grooves that passed every other test
    #: there measured 0.13.
    min_relative_contrast: float = 0.2
    #: the smallest measured diameter kept: 90 % of the smallest hole measured (20 px);
    #: the detector's floor (``detect.min_diameter_px``, 16 px) is lower because a coarse
    #: radius is rough.  Most texture crossings that passed every other test measured
    #: 16.1-17.4 px (eight station sets of 200 frames: 2 of 3; the wide envelope's 120
    #: bench frames: 3 of 3)
    min_diameter_px: float = 18.0
    #: refine whole holes' diameter and centre by a blurred-disc intensity fit with a
    #: honing-groove model (``photometric.py``); on by default since its annulus was
    #: narrowed and its iterations cut; None: the rays only (docs/vision.md)
    photometric: PhotometricConfig | None = PhotometricConfig()
    #: rays per px of rim on holes clear of the border when the photometric fit is on;
    #: 1.0 keeps the rays as without it (they start the fit, and give cut holes' centres)
    ray_density_photometric: float = 1.0
    #: a whole hole's centre: the rays' moved this share of the way to the photometric
    #: fit's.  Without flat-fielding the fit's centre was biased by the vignetting and the
    #: blend was best (six dev sets, 1,748 whole holes, centre median / 99th percentile /
    #: worst / count over 0.1 px: the rays' 0.0243 / 0.112 / 0.197 / 30, 0.5: 0.0212 /
    #: 0.089 / 0.136 / 8, the fit's 0.0231 / 0.117 / 0.189 / 35).  Flat-fielded, the
    #: fit's own centre is best: dev 3000 + 9000 (585 holes) median 0.0211 (0.5, not
    #: flat-fielded) -> 0.0191 (0.5) / 0.0171 (1); dev 5000, 11000, 13000, 15000 (1,201
    #: holes) 0.0213 -> 0.0189 / 0.0172 (0.85) / 0.0169 (1), 90th percentile 0.049 ->
    #: 0.039, over 0.1 px 4 -> 2
    photometric_centre_weight: float = 1.0
    #: flat-field each hole by the frame's illumination (``illumination.py``: vignetting
    #: multiplies the hole's level too, and the fit's constant hole level read its
    #: gradient as a displaced rim) before the photometric fit; grain-only dev frames,
    #: the fit's centre median 0.0218 -> 0.0164 px (0.0158 with no vignetting at all)
    flat_field: bool = True
    #: drop a whole candidate whose pixels the blurred-disc model cannot fit (it runs
    #: more than 2 px away from the rays' circle).  On 400 wide-envelope and 400
    #: station-envelope dev frames (seeds 3000-3399; 5000-5199, 11000-11199), with the
    #: confidence floor off, every true whole hole converged (1,195) and each of the 11
    #: other candidates that reached the fit (crossings of dark honing grooves) ran away
    reject_unfitted_whole: bool = True
    #: the wide ray search starts at this share of the coarse radius for a candidate cut
    #: by the border (0.5 otherwise): its centroid lies inside the frame, up to ~0.4 r
    #: from a centre on the border, so the rim's nearest part can be closer than 0.5 r.
    #: Cut holes found (400 frames each): station 1000 195 -> 196, 20000 203 -> 203,
    #: wide 1000 190 -> 194 of 202; whole holes unchanged
    wide_inner_border: float = 0.15
    #: a whole hole's diameter and centre uncertainties (``HoleMeasurement.diameter_u_px``,
    #: ``x_u_px``, ``y_u_px``) come from the photometric fit: "correlated" (the default
    #: since round 13) takes its kernel estimate of the least-squares sandwich from the
    #: residuals' own spatial correlation (``PhotometricFit.r_u``, ``cx_u``, ``cy_u``:
    #: the grain blurred by the camera is correlated noise) times a factor per quantity;
    #: "white" its white-noise standard deviations times ``uncertainty_factor`` (rounds
    #: 7-12).  On the dev frames (station seeds 3000-3149 + 5000-5149, 429 whole holes,
    #: round 13's fit), at the factor that makes +/- 2 u hold 95 % (white 1.65 / 1.38,
    #: correlated 1.27 / 1.18 for the diameter / the centre), +/- 3 u holds 99.30 % /
    #: 99.30 % for "white" and 99.53 % / 99.65 % for "correlated", with a median u over
    #: the frame-aware Cramer-Rao bound of 1.22 / 1.09 and 1.15 / 1.13 (docs/vision.md,
    #: Each hole's uncertainty)
    uncertainty_factor: float = 1.6
    uncertainty_model: str = "correlated"
    #: the diameter's factor on the correlated u: 1.35 (dev frames above: +/- 2 u holds
    #: 96.7 %, +/- 3 u 99.53 %, median u / bound 1.22).  Above 1 because what the
    #: residuals do not show, the groove model's own error absorbed by the radius, is not
    #: in the sandwich
    correlated_uncertainty_factor: float = 1.35
    #: the centre's (x and y pooled): 1.25 (96.3 %, 99.65 %, 1.20)
    correlated_centre_uncertainty_factor: float = 1.25
    #: the factors on a grain-aware fit's uncertainties (``gls_steps``: the inverse normal
    #: matrix scaled by the chi-square), diameter and centre: set on dev frames 3000-3149
    #: and 5000-5149 (429 holes) for +/- 2u to cover ~95 % (diameter 1.25: 96.3 % and
    #: 99.5 % within +/- 3u).  The diameter's errors have a heavier tail than its u: on
    #: the same seeds at 400 frames, with round 15's slope, 1.25 holds +/- 2u 96.9 % and
    #: +/- 3u 99.42 %, and no factor holds both bands by a margin.  The centre's, first
    #: 1.05 there, was re-set on the same seeds taken to 400 frames each (1,212 holes,
    #: 2,424 coordinates), where 1.05 held +/- 2u 94.3 % and +/- 3u 99.67 %: 1.10 holds
    #: 95.3 % and 99.71 % (95.5 % wants 1.11, 99.73 % 1.09).  Since round 18 a hole that
    #: holds the frame's shared blur carries that blur's own uncertainty too
    #: (``PhotometricFit.r_ds``; 83 % of the holes, whose u grows by 9.5 % at the median
    #: and 22 % at the 90th percentile), which the diameter's 1.25 had absorbed on
    #: average: re-set on the same 1,212 holes (round 18's fit), 1.10 holds +/- 2u 96.3 %
    #: and +/- 3u 99.59 % (1.05: 95.5 % / 99.59 %; 1.15: 96.6 % / 99.83 %; the old u at
    #: 1.25: 96.5 % / 99.59 %), and 95 % within +/- 2u wants 1.02 instead of 1.15
    gls_uncertainty_factor: float = 1.10
    gls_centre_uncertainty_factor: float = 1.10
    #: a candidate whose wide ray search (72 rays) has fewer rays on one RANSAC circle is
    #: dropped before the narrow search: no true hole had fewer than 24 (dev frames,
    #: station seeds 3000-3199 + 5000-5199, 801 holes; wide 3000-3199, 396 holes, cut holes
    #: included), and a quarter of the station envelope's texture candidates have fewer
    #: than 18 (they were dropped later anyway, by the coverage and inlier tests)
    min_wide_inliers: int = 18
    #: the frame's whole holes share one blur (one lens, one focus): each hole's
    #: photometric fit is run again with the blur held at the frame's, the mean of the
    #: holes' own fitted blurs weighted by their precision (since round 16 from the
    #: residuals' spatial correlation, ``PhotometricFit.blur_u``: the white-noise figure
    #: overweighs a grainy hole; dev seeds 3000 + 5000, 200 frames each, diameter RMS z
    #: 1.090 -> 1.076 and beyond 3 sigma 1.02 % -> 0.68 %), when they agree with it: a
    #: lens whose blur changes across the field keeps each hole's own.  They disagree when
    #: the chi-square of their blurs about the mean (n - 1 degrees of freedom) has a
    #: p-value below ``share_blur_alpha``.  Round 16 and before gated at 4 per degree of
    #: freedom, a false alarm in 4.6 % of two-hole frames and 1.8 % of three-hole frames,
    #: and a false alarm is the frame whose hole read its blur worst, which then kept it
    #: (bench seed 1000: 8 of 197 frames, 21 holes at diameter RMS z 1.91, three of the
    #: eight diameters beyond 3 sigma; docs/vision-history.md, round 17)
    share_blur: bool = True
    share_blur_alpha: float = 0.001
    #: grain-aware Gauss-Newton steps in each hole's last photometric fit
    #: (``PhotometricConfig.gls_steps``, ``gls.py``: the wall's grain as correlated noise;
    #: docs/vision-history.md, round 14); 0: the weighted fit only
    gls_steps: int = 1
    #: the honing grooves' profiles read over each hole's wide neighbourhood
    #: (``grooves.py``), the hole's ring giving only their depth there; else each hole
    #: reads them from its ring alone (docs/vision-history.md, round 13)
    frame_grooves: bool = True
    #: the hatch's two directions read from the frame (``grooves.frame_hatch``), the
    #: photometric config's ``groove_angles_deg`` the nominal it falls back to when the
    #: frame shows no clear hatch: the honing angle is the part's, not the station's
    read_hatch: bool = True
    #: ... read over a window this far (px) beyond 1.3 x each candidate's radius, not the
    #: whole frame (None): a lens's distortion bends a straight groove across a frame.
    #: 250 since round 19 (150 before): more of each groove's line in its profile.  Dev
    #: seeds 3000 / 5000 (400 frames each, paired over the same holes), with the ring's
    #: local profile per side (``PhotometricConfig.groove_frame_local_sides``): diameter
    #: RMS z 1.069 / 1.077 -> 1.058 / 1.067, centre 1.077 / 1.055 -> 1.065 / 1.047; 400 px
    #: was no better.  The profiles' cost grows with the window's area, the vision's time
    #: by ~2 % (docs/vision-history.md, round 19)
    groove_window_px: float | None = 250.0


@dataclass(frozen=True)
class HoleMeasurement:
    x_px: float
    y_px: float
    diameter_px: float
    partial: bool
    confidence: float
    fit_rms_px: float
    edge_contrast_dn: float
    edge_sigma_px: float
    n_edge_points: int
    coverage: float  # share of the rim measured (valid rays / rays)
    major_px: float | None = None
    minor_px: float | None = None
    angle_deg: float | None = None
    diameter_mm: float | None = None
    #: standard uncertainty (k = 1) of the diameter from this frame alone, whole holes
    #: with a photometric fit only (``MeasureConfig.uncertainty_factor``)
    diameter_u_px: float | None = None
    diameter_u_mm: float | None = None
    #: the same for the centre's x and y (px)
    x_u_px: float | None = None
    y_u_px: float | None = None
    #: with a calibration that holds its map's uncertainty: that uncertainty at the hole's
    #: centre (px, k = 1, the larger of x and y), a systematic term of the calibration
    #: common to every frame, apart from the per-frame ``x_u_px`` / ``y_u_px``
    map_u_px: float | None = None

    def to_dict(self) -> dict:
        d = asdict(self)
        return {k: v for k, v in d.items() if v is not None}


def _profile_weights(sigma2: np.ndarray, profiles: np.ndarray, peak: np.ndarray) -> np.ndarray:
    """Prior weights (0..1) of the rays from the quality of their edge profiles.

    A blurred rim has one edge profile all round.  A ray whose profile is twice as wide
    or half as narrow has merged with a groove or grain: weight 0.  Otherwise the
    weight falls with the RMS deviation of the ray's profile (scaled to its peak) from
    the rim's median profile, relative to that deviation's median over the rim:
    w = 1 / (1 + (dev / median dev)^2), i.e. inverse-variance weighting if a ray's
    edge error grows in proportion to how much texture or noise distorts its profile.
    """
    return _profile_weights_kernel(np.ascontiguousarray(sigma2, dtype=np.float64),
                                   np.ascontiguousarray(profiles, dtype=np.float64),
                                   np.ascontiguousarray(peak, dtype=np.float64))


@njit(cache=True, nogil=True)
def _profile_weights_kernel(sigma2, profiles, peak):
    n, m = profiles.shape
    med = np.median(sigma2[np.isfinite(sigma2)])
    prof = np.empty((n, m))
    for i in range(n):
        p = max(peak[i], 1e-9)
        for j in range(m):
            prof[i, j] = profiles[i, j] / p
    # the rays' windows are aligned on their discrete peaks (+/- half a step): fit the
    # template and its derivative (a sub-sample shift, to first order) by least squares
    # and keep what neither explains
    tmpl = np.empty(m)
    for j in range(m):
        tmpl[j] = np.median(prof[:, j])
    grad = gradient_1d(tmpl)
    g00 = g01 = g11 = 0.0
    for j in range(m):
        g00 += tmpl[j] * tmpl[j]
        g01 += tmpl[j] * grad[j]
        g11 += grad[j] * grad[j]
    det = g00 * g11 - g01 * g01
    dev = np.empty(n)
    for i in range(n):
        b0 = b1 = 0.0
        for j in range(m):
            b0 += tmpl[j] * prof[i, j]
            b1 += grad[j] * prof[i, j]
        c0 = (g11 * b0 - g01 * b1) / det if det != 0.0 else 0.0
        c1 = (g00 * b1 - g01 * b0) / det if det != 0.0 else 0.0
        acc = 0.0
        for j in range(m):
            e = prof[i, j] - c0 * tmpl[j] - c1 * grad[j]
            acc += e * e
        dev[i] = np.sqrt(acc / m)
    scale = max(np.median(dev), 1e-6)
    out = np.zeros(n)
    for i in range(n):
        ratio = sigma2[i] / med
        if ratio > 0.5 and ratio < 2.0:
            out[i] = 1.0 / (1.0 + (dev[i] / scale) ** 2)
    return out


def _fine(image: np.ndarray, cx: float, cy: float, r_min: float, r_max: float, n_rays: int, step_px: float = 0.5):
    """Gradient over an ROI holding radii up to ``r_max`` and the rays' edges."""
    h, w = image.shape
    pad = r_max + KERNEL_RADIUS_PX + 3
    x0, x1 = max(int(np.floor(cx - pad)), 0), min(int(np.ceil(cx + pad)) + 1, w)
    y0, y1 = max(int(np.floor(cy - pad)), 0), min(int(np.ceil(cy + pad)) + 1, h)
    if x1 - x0 < 2 * KERNEL_RADIUS_PX + 3 or y1 - y0 < 2 * KERNEL_RADIUS_PX + 3:
        # a centre (a refinement that ran off) so far past the border that no ray fits
        # in the frame: no edges, the hole cut by the border (and rejected as such)
        gx = gy = np.zeros((max(y1 - y0, 0), max(x1 - x0, 0)), np.float32)
    else:
        gx, gy = gradient(image[y0:y1, x0:x1])
    return ray_edges(gx, gy, (x0, y0), (h, w), (cx, cy), r_min, r_max, n_rays, step_px)


def measure_candidate(
    image: np.ndarray,
    cand: Candidate,
    cfg: MeasureConfig,
    calibration: CameraCalibration | None = None,
    rng: np.random.Generator | None = None,
    illumination: Illumination | None = None,
) -> HoleMeasurement | None:
    """Sub-pixel measurement of one candidate, or None when it is not a hole.

    ``illumination``: the frame's illumination field; the photometric fit flat-fields the
    hole by its local gradient (none: as if the illumination were flat)."""
    return _measure_candidate(image, cand, cfg, calibration, rng, illumination)[0]


@dataclass(frozen=True)
class _Rays:
    """What the rays found of a candidate: the start of the photometric fit and the
    figures the acceptance judges."""

    edges: object
    fit: object
    whole: bool
    cx: float
    cy: float
    r: float
    coverage: float
    inlier_fraction: float
    sigma_px: float
    contrast_dn: float
    psf2: float
    r_true: float


def _ray_stage(image: np.ndarray, cand: Candidate, cfg: MeasureConfig, rng: np.random.Generator | None = None
               ) -> _Rays | None:
    """The rays' part of ``measure_candidate``: None when the candidate is no hole."""
    rng = rng if rng is not None else np.random.default_rng(0)
    r0 = cand.radius_px
    # pass 1: wide search (the coarse radius is good to ~1 coarse pixel for whole
    # holes; for cut holes the centroid is pulled inwards, hence the wide window)
    inner = cfg.wide_inner_border if cand.touches_border else 0.5
    wide = _fine(image, cand.x_px, cand.y_px, inner * r0, 1.6 * r0 + 4, 72, step_px=1.0)
    if len(wide.points) < cfg.min_valid_rays // 2:
        return None
    inl = ransac_circle(wide.points, 1.0, rng)
    if inl.sum() < cfg.min_wide_inliers:
        return None  # no circle agrees with enough of the rays: texture, not a hole
    # only a start for the narrow search (which recasts its rays beyond 0.3 px): a few
    # IRLS steps suffice
    first = robust_circle(wide.points[inl], taubin_circle(wide.points[inl]), min_scale_px=0.2, iterations=5)
    cx, cy, r = first.cx, first.cy, first.r
    # pass 2 (twice: a cut hole's first centre may be off by a pixel): narrow window
    for attempt in range(2):
        if not (2.0 < r < cfg.detect.max_diameter_px):
            return None
        # about one ray per px of rim; half as many where the photometric fit will give
        # the geometry and the rays only judge the rim (roundness, inliers, edge width)
        density = 1.0
        if cfg.photometric is not None:
            reach = r + cfg.fine_window_px + KERNEL_RADIUS_PX + 2
            h, w = image.shape
            if reach <= cx <= w - 1 - reach and reach <= cy <= h - 1 - reach:
                density = cfg.ray_density_photometric
        n_rays = int(np.clip(round(2 * np.pi * r * density), 64, 360))
        edges = _fine(image, cx, cy, max(r - cfg.fine_window_px, 1.0), r + cfg.fine_window_px, n_rays)
        if len(edges.points) < cfg.min_valid_rays:
            return None
        # ovality only where the whole rim is seen: on a short arc the second harmonic
        # trades off against the radius and the centre
        whole = not edges.cut_by_border
        fit = robust_circle(edges.points, (cx, cy, r), weights=_profile_weights(edges.sigma2, edges.profiles, edges.peak), oval=whole)
        moved = np.hypot(fit.cx - cx, fit.cy - cy)
        cx, cy, r = fit.cx, fit.cy, fit.r
        # rays cast from a centre 0.3 px off are still radial to within 0.3/r rad: the
        # edge they find moves by a negligible (0.3/r)^2 r / 2; recast only beyond that
        if moved < 0.3:
            break
    coverage = edges.n_valid / edges.n_rays
    inlier_fraction = fit.inliers.sum() / max(edges.n_valid, 1)
    if coverage < cfg.min_coverage or inlier_fraction < cfg.min_inlier_fraction:
        return None
    sigma_px = float(np.sqrt(profile_width2(edges.profiles[fit.inliers], edges.step_px)))
    if not np.isfinite(sigma_px):
        return None  # no inlier's profile to read the edge's width from (gates relaxed to 0)
    if relative_contrast(image, cx, cy, r, sigma_px) < cfg.min_relative_contrast:
        return None  # too faint for a through-hole: crossing grooves
    # a Gaussian-blurred step of height c has a derivative peak c / (sqrt(2 pi) sigma)
    contrast_dn = float(median(edges.peak[fit.inliers]) * np.sqrt(2 * np.pi) * sigma_px)
    psf2 = psf_variance(sigma_px**2, r)
    r_true = deblurred_radius(r, float(np.sqrt(psf2)))
    return _Rays(edges, fit, whole, cx, cy, r, coverage, inlier_fraction, sigma_px, contrast_dn, psf2, r_true)


def _measure_candidate(
    image: np.ndarray,
    cand: Candidate,
    cfg: MeasureConfig,
    calibration: CameraCalibration | None = None,
    rng: np.random.Generator | None = None,
    illumination: Illumination | None = None,
    frame_blur: float | None = None,
    frame_grooves=None,
    rays: _Rays | None = None,
    fit_cache: dict | None = None,
    frame_blur_sd: float = 0.0,
) -> tuple[HoleMeasurement | None, PhotometricFit | None, _Rays | None]:
    """``measure_candidate``, its photometric fit (None without one) and its rays' stage
    (``rays``: one already run, not run again).  ``frame_blur``: the blur s the frame's
    holes share (``MeasureConfig.share_blur``), held fixed in the photometric fit instead
    of the rays' start and a free blur; ``frame_blur_sd`` its standard deviation, which
    the hole's uncertainties carry through the fit's sensitivity to the blur
    (``PhotometricFit.r_ds``).  ``frame_grooves``: the grooves' profiles for the
    photometric fit (``grooves.FrameGrooves``), or a function that reads them, called
    only when the fit runs.  ``fit_cache``: kept between a hole's two photometric fits
    (the first with its own blur, the second with the frame's), which then share their
    annulus, ring and groove model."""
    ph = None
    if rays is None:
        rays = _ray_stage(image, cand, cfg, rng)
    if rays is None:
        return None, ph, None
    edges, fit, whole, cx, cy, r = rays.edges, rays.fit, rays.whole, rays.cx, rays.cy, rays.r
    coverage, inlier_fraction, sigma_px = rays.coverage, rays.inlier_fraction, rays.sigma_px
    contrast_dn, psf2, r_true = rays.contrast_dn, rays.psf2, rays.r_true
    shift = np.zeros(2)
    diameter_u = x_u = y_u = None
    if whole and cfg.photometric is not None and np.isfinite(psf2):
        # the image's own blur: the rays' width less our smoothing and bilinear sampling
        blur = float(np.sqrt(max(psf2 - SMOOTH_SIGMA_PX**2 - 1.0 / 6.0, 0.09)))
        grad = illumination.relative_gradient(cx, cy) if illumination is not None else None
        curv = illumination.relative_curvature(cx, cy) if illumination is not None else None
        pcfg = cfg.photometric
        roi_blur = blur
        if frame_blur is not None:
            blur, pcfg = frame_blur, replace(pcfg, fit_blur=False)
        if callable(frame_grooves):
            frame_grooves = frame_grooves()
        ph = refine_hole(image, cx, cy, r_true, blur, pcfg, illumination_grad=grad, frame_grooves=frame_grooves,
                         roi_blur_px=roi_blur, cache=fit_cache, illumination_curv=curv)
        if ph is not None and not ph.converged and cfg.reject_unfitted_whole:
            return None, ph, rays  # the pixels around this whole rim are no blurred disc
        if ph is not None and ph.converged:
            # the radius from the intensities (it uses the textureless hole side and
            # the groove model); the centre moved ``photometric_centre_weight`` of the
            # way to the fit's (all of it since the hole is flat-fielded: see the setting)
            r_true = ph.r
            if ph.gls:
                k, kc = cfg.gls_uncertainty_factor, cfg.gls_centre_uncertainty_factor
                r_sd, cx_sd, cy_sd = ph.r_u, ph.cx_u, ph.cy_u
            elif cfg.uncertainty_model == "correlated":
                k, kc = cfg.correlated_uncertainty_factor, cfg.correlated_centre_uncertainty_factor
                r_sd, cx_sd, cy_sd = ph.r_u, ph.cx_u, ph.cy_u
            else:
                k = kc = cfg.uncertainty_factor
                r_sd, cx_sd, cy_sd = ph.r_sd, ph.cx_sd, ph.cy_sd
            if frame_blur is not None and frame_blur_sd > 0 and np.isfinite(ph.r_ds):
                # the held blur's own error moves the hole too (independent of the fit's
                # error at the true blur, to first order: the blur's estimate comes from
                # what the other parameters leave unexplained)
                r_sd, cx_sd, cy_sd = (float(np.hypot(a, frame_blur_sd * d)) for a, d in
                                      ((r_sd, ph.r_ds), (cx_sd, ph.cx_ds), (cy_sd, ph.cy_ds)))
            if np.isfinite(r_sd):
                diameter_u = k * 2.0 * r_sd
            if np.isfinite(cx_sd) and np.isfinite(cy_sd) and cfg.photometric_centre_weight == 1.0:
                # the centre is the fit's own (a blend with the rays' has no such figure)
                x_u, y_u = kc * cx_sd, kc * cy_sd
            shift = cfg.photometric_centre_weight * np.array([ph.cx - cx, ph.cy - cy])
            cx, cy = cx + shift[0], cy + shift[1]
    pts = edges.points + shift + (r_true - r) * edges.directions
    map_u = None
    if calibration is not None:
        mu = calibration.undistort_u_px(np.array([[cx, cy]]))
        if mu is not None:
            map_u = float(mu.max())
        pts = calibration.undistort_px(pts)
        cal = robust_circle(pts[fit.inliers], taubin_circle(pts[fit.inliers]), oval=whole)
        cx, cy, r_true = cal.cx, cal.cy, cal.r
        rms_px = cal.rms_px  # a distorted rim is no circle: judge the fit where it is one
    else:
        rms_px = fit.rms_px  # ovality is in the model, so this is roundness
    if rms_px > cfg.max_rms_px:
        return None, ph, rays
    diameter = 2.0 * r_true
    if not (cfg.min_diameter_px <= diameter <= cfg.detect.max_diameter_px):
        return None, ph, rays
    ell = fit_ellipse_direct(pts[fit.inliers]) if not edges.cut_by_border else None
    # heuristic confidence: share of consistent edge points, share of rim seen (full
    # weight from half the rim), and the measurement's quality: the rays' scatter
    # against a 0.25 px residual scale or, for a whole hole with a photometric fit, its
    # own diameter uncertainty against ``confidence_u_ref_px`` if that judges it better
    quality = 1.0 / (1.0 + (rms_px / 0.25) ** 2)
    if diameter_u is not None and cfg.confidence_u_ref_px:
        quality = max(quality, 1.0 / (1.0 + (diameter_u / cfg.confidence_u_ref_px) ** 2))
    confidence = float(inlier_fraction * min(1.0, 2.0 * coverage) * quality)
    if confidence < cfg.min_confidence:
        return None, ph, rays
    return HoleMeasurement(
        x_px=float(cx),
        y_px=float(cy),
        diameter_px=float(diameter),
        partial=bool(edges.cut_by_border),
        confidence=float(np.clip(confidence, 0.0, 1.0)),
        fit_rms_px=float(rms_px),
        edge_contrast_dn=contrast_dn,
        edge_sigma_px=sigma_px,
        n_edge_points=int(fit.inliers.sum()),
        coverage=float(coverage),
        major_px=2 * ell[2] if ell else None,
        minor_px=2 * ell[3] if ell else None,
        angle_deg=ell[4] if ell else None,
        diameter_u_px=diameter_u,
        x_u_px=x_u,
        y_u_px=y_u,
        map_u_px=map_u,
    ), ph, rays


def relative_contrast(image: np.ndarray, cx: float, cy: float, r: float, blur_px: float) -> float:
    """(wall - inside) / wall: medians of the pixels inside the rim's blur and of a 6 px
    ring outside it, over the part of both within the frame (NaN when either is empty)."""
    h, w = image.shape
    r_wall = r + 2 * blur_px + 1
    r_out = r_wall + 6
    x0, x1 = max(int(cx - r_out), 0), min(int(cx + r_out) + 2, w)
    y0, y1 = max(int(cy - r_out), 0), min(int(cy + r_out) + 2, h)
    if x1 <= x0 or y1 <= y0:
        return float("nan")
    dx = np.arange(x0, x1) - cx
    dy = np.arange(y0, y1) - cy
    d2 = dx[None, :] ** 2 + dy[:, None] ** 2
    v = image[y0:y1, x0:x1]
    r_in = max(r - 2 * blur_px - 0.5, 0.5 * r)
    inside, ring = v[d2 < r_in * r_in], v[(d2 > r_wall * r_wall) & (d2 < r_out * r_out)]
    if inside.size == 0 or ring.size == 0:
        return float("nan")
    wall = median(ring.astype(np.float64))
    return float((wall - median(inside.astype(np.float64))) / max(wall, 1.0))


def measure_holes(
    image: np.ndarray,
    mm_per_px: float | None = None,
    calibration: CameraCalibration | None = None,
    cfg: MeasureConfig = MeasureConfig(),
) -> list[HoleMeasurement]:
    """All holes of a grey (or BGR) frame of 8 or 16 bits, sorted by y then x.

    The scale comes from ``mm_per_px`` or else from the calibration's own scale; when
    neither is known ``diameter_mm`` stays None.
    """
    image = to_8bit(to_grey(image))
    if mm_per_px is None and calibration is not None:
        mm_per_px = calibration.mm_per_px
    rng = np.random.default_rng(0)  # fixed: the same frame always gives the same result
    found: list[HoleMeasurement] = []
    # a finer camera shows the same holes larger in px: the detector's and the acceptance's
    # largest diameter follow the scale when it is known (``detect.for_scale``)
    cfg = replace(cfg, detect=for_scale(cfg.detect, mm_per_px))
    candidates = detect_candidates(image, cfg.detect)
    illumination = (estimate_illumination(image)
                    if candidates and cfg.flat_field and cfg.photometric is not None else None)
    kept: list[tuple[Candidate, PhotometricFit | None, object, _Rays, dict]] = []
    grooves_on = bool(cfg.frame_grooves and cfg.photometric is not None and cfg.photometric.groove_angles_deg)
    masks = [(c.x_px, c.y_px, 1.3 * c.radius_px + 4.0) for c in candidates]
    if candidates and cfg.read_hatch and cfg.photometric is not None and cfg.photometric.groove_angles_deg:
        hatch = frame_hatch(image, masks, cfg.photometric.groove_angles_deg)
        cfg = replace(cfg, photometric=replace(cfg.photometric, groove_angles_deg=hatch))
    level = _Lazy(lambda: wall_level(image, masks))
    whole_frame = _Lazy(lambda: frame_grooves(image, masks, cfg.photometric.groove_angles_deg, level=level()))
    # the grain-aware steps (``gls_steps``) run once per hole, in the last fit: the first
    # fits are weighted only
    gls = cfg.photometric is not None and cfg.gls_steps > 0
    first_cfg, last_cfg = cfg, cfg
    if cfg.photometric is not None:
        first_cfg = replace(cfg, photometric=replace(cfg.photometric, gls_steps=0))
        last_cfg = replace(cfg, photometric=replace(cfg.photometric, gls_steps=cfg.gls_steps))
    for cand in candidates:
        fg = None
        if grooves_on:
            fg = whole_frame
            if cfg.groove_window_px is not None:
                half = cand.radius_px * 1.3 + cfg.groove_window_px
                window = (int(cand.x_px - half), int(cand.y_px - half), int(cand.x_px + half) + 1,
                          int(cand.y_px + half) + 1)
                fg = _Lazy(lambda window=window: frame_grooves(image, masks, cfg.photometric.groove_angles_deg,
                                                               window=window, level=level()))
        fit_cache: dict = {}
        m, ph, rays = _measure_candidate(image, cand, first_cfg, calibration, rng, illumination, frame_grooves=fg,
                                         fit_cache=fit_cache)
        if m is None:
            continue
        # two candidates (a hole split by a deep groove) may converge on one hole
        if any(np.hypot(m.x_px - o.x_px, m.y_px - o.y_px) < 0.5 * o.diameter_px / 2 for o in found):
            continue
        found.append(m)
        kept.append((cand, ph, fg, rays, fit_cache))
    shared = _frame_blur([k[1] for k in kept]) if cfg.share_blur else None
    frame_blur = shared.mean if shared is not None and shared.p_value >= cfg.share_blur_alpha else None
    if frame_blur is not None or gls:
        for i, (cand, ph, fg, rays, fit_cache) in enumerate(kept):
            if ph is not None and ph.converged:
                m2, _, _ = _measure_candidate(image, cand, last_cfg, calibration, None, illumination,
                                              frame_blur=frame_blur, frame_grooves=fg, rays=rays, fit_cache=fit_cache,
                                              frame_blur_sd=shared.sd if frame_blur is not None else 0.0)
                if m2 is not None:
                    found[i] = m2
    out: list[HoleMeasurement] = []
    for m in found:
        if mm_per_px is not None:
            m = HoleMeasurement(**{**asdict(m), "diameter_mm": m.diameter_px * mm_per_px,
                                   "diameter_u_mm": None if m.diameter_u_px is None else m.diameter_u_px * mm_per_px})
        out.append(m)
    return sorted(out, key=lambda m: (m.y_px, m.x_px))


class _Lazy:
    """A value computed on the first call, then kept (a candidate's grooves, read only
    if its photometric fit runs)."""

    def __init__(self, make):
        self._make, self._done, self._value = make, False, None

    def __call__(self):
        if not self._done:
            self._value, self._done = self._make(), True
        return self._value


class FrameBlur(NamedTuple):
    """The blur a frame's holes share (``_frame_blur``)."""

    mean: float  # px, the holes' fitted blurs weighted by their precision
    sd: float  # px, its standard deviation from theirs (1 / sqrt of the summed precisions)
    chi2: float  # of the holes' blurs about the mean, per degree of freedom
    dof: int  # the holes less one
    p_value: float  # of chi2 * dof on dof degrees of freedom: the chance of a worse spread


def _frame_blur(fits: list[PhotometricFit | None]) -> FrameBlur | None:
    """The blur the frame's converged photometric fits share: their precision-weighted
    mean, and how well their blurs agree with it; None with fewer than two such fits."""
    ok = [f for f in fits if f is not None and f.converged and np.isfinite(f.blur_sd)]
    s = np.array([f.blur_px for f in ok])
    sd = np.array([f.blur_u if np.isfinite(f.blur_u) else f.blur_sd for f in ok])
    if s.size < 2 or np.any(sd <= 0):
        return None
    w = 1.0 / (sd * sd)
    mean = float(np.sum(w * s) / np.sum(w))
    q, dof = float(np.sum(w * (s - mean) ** 2)), s.size - 1
    return FrameBlur(mean, float(np.sqrt(1.0 / np.sum(w))), q / dof, dof, float(chdtrc(dof, q)))


@functools.cache
def warm_up() -> int:
    """Load (or, the first time after an install or a code change, compile) the vision
    stage's compiled kernels by measuring a small synthetic hole, so that the first
    frame of the first inspection does not pay for it (loading: ~0.2 s; compiling:
    ~5 s, once, cached next to the code).  Once per process; returns the number of
    holes found (1)."""
    n = 160
    yy, xx = np.mgrid[0:n, 0:n].astype(np.float64)
    inside = np.hypot(xx - 80.3, yy - 79.6) < 22.0
    rng = np.random.default_rng(0)
    image = np.where(inside, 50.0, 150.0) + rng.normal(0.0, 2.0, (n, n))
    image = cv2.GaussianBlur(image, (0, 0), 1.2)
    return len(measure_holes(np.clip(np.rint(image), 0, 255).astype(np.uint8)))
