"""Sub-pixel hole measurement on rendered frames with known ground truth.

Accuracy bars (the vision issue's goal, on whole holes >= 20 px): centre error
<= 0.1 px and diameter error <= 0.15 px at worst, medians <= 0.05 px; no phantom
holes on textured walls; holes cut by the frame border flagged ``partial``.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from sim.camera.render import FrameParams, HoleSpec, random_frame, random_holes, random_params, render_frame
from station.vision import measure_holes
from station.vision.edges import deblurred_radius
from station.vision.fit import fit_ellipse_direct, ransac_circle, robust_circle, taubin_circle
from station.vision.measure import MeasureConfig
from station.vision.scoring import Score, score_frame


def _score(frame, holes) -> Score:
    truths = [(h.x_px, h.y_px, h.diameter_px, h.partial) for h in frame.holes]
    return score_frame(truths, [(m.x_px, m.y_px, m.diameter_px, m.partial) for m in holes])


# conditions where the strict bars hold, each frame with honing texture and vignetting,
# noisy to clean sensors: large holes (60-100 px) over the whole envelope (blur 0.8-2
# px, contrast 40-85 %); small holes (20-30 px) at blur <= 1.4 px and contrast >= 55 %.
# Small holes at 2 px blur or 40 % contrast are the known limit, tested on their own.
CONDITIONS = [
    dict(blur_sigma_px=b, contrast=c, gain_e_per_dn=g, sizes=s)
    for s, blurs, contrasts in (((20.0, 30.0), (0.8, 1.4), (0.55, 0.85)), ((60.0, 100.0), (0.8, 2.0), (0.4, 0.85)))
    for b in blurs
    for c in contrasts
    for g in (20.0, 60.0)
]


def _frame(i: int, blur_sigma_px: float, contrast: float, gain_e_per_dn: float, sizes, lens=None):
    rng = np.random.default_rng(100 + i)
    p = random_params(rng, blur_sigma_px=blur_sigma_px, gain_e_per_dn=gain_e_per_dn, lens=lens)
    p = replace(p, hole_level_dn=p.wall_level_dn * (1.0 - contrast))
    holes = random_holes(rng, p, n_whole=3, diameter_range_px=sizes)
    return render_frame(p, holes, seed=i)


@pytest.fixture(scope="module")
def envelope_score() -> Score:
    total = Score()
    for i, cond in enumerate(CONDITIONS):
        f = _frame(i, **cond)
        total.add(_score(f, measure_holes(f.image)))
    return total


def test_accuracy_across_blur_noise_contrast_size(envelope_score):
    s = envelope_score.summary()
    assert s["holes_measured"] == 3 * len(CONDITIONS)  # every hole found
    assert s["misses"] == 0 and s["phantoms"] == 0
    assert s["median_centre_err_px"] <= 0.05
    assert s["median_diameter_err_px"] <= 0.05
    assert s["worst_centre_err_px"] <= 0.10
    assert s["worst_diameter_err_px"] <= 0.15


def test_small_holes_under_heavy_blur_are_measured_near_their_cramer_rao_bound():
    """20-30 px holes at 2 px blur or 40 % contrast (the envelope's hardest, where the
    absolute worst-case bars do not hold): all found, no phantoms, and each hole's error
    judged against its own Cramer-Rao bound (``station bench vision-bound``: the sensor's
    noise and the wall's grain as rendered, blur and wall slope fitted; optimistic, the
    grooves count as known).

    Efficiency measured on 608 fresh holes (seeds 20000-20399, docs/vision.md): RMS of each
    hole's error over its bound 1.20 for the diameter, 1.13 per axis for the centre. With
    18 holes an RMS ratio scatters by ~1 / sqrt(2 n) = 17 %: the bars are that efficiency
    + 2.5 of those, and no single hole beyond 4 of its (efficiency-scaled) sigmas. They
    fail if the fit falls clearly below the efficiency it has on the bench, not by chance.
    """
    from station.bench.vision_bound import cases_from_frame, hole_bound

    total, z_d, z_c = Score(), [], []
    cases = [(2.0, 0.4, 20.0), (2.0, 0.4, 60.0), (2.0, 0.85, 20.0), (2.0, 0.85, 60.0), (0.8, 0.4, 20.0), (0.8, 0.4, 60.0)]
    for i, (b, c, g) in enumerate(cases):
        f = _frame(200 + i, blur_sigma_px=b, contrast=c, gain_e_per_dn=g, sizes=(20.0, 30.0))
        found = measure_holes(f.image)
        total.add(_score(f, found))
        whole = [h for h in f.holes if not h.partial]
        for t, case in zip(whole, cases_from_frame(f)):
            m = min(found, key=lambda m: np.hypot(m.x_px - t.x_px, m.y_px - t.y_px))
            sd, cov = hole_bound(case)
            z_d.append((m.diameter_px - t.diameter_px) / sd)
            z_c.append(np.hypot(m.x_px - t.x_px, m.y_px - t.y_px) / np.sqrt(0.5 * np.trace(cov)))
    s = total.summary()
    assert s["holes_measured"] == 3 * len(cases) and s["phantoms"] == 0
    assert s["median_centre_err_px"] <= 0.06 and s["median_diameter_err_px"] <= 0.1
    z_d, z_c = np.array(z_d), np.array(z_c)
    n = len(z_d)
    allowance = 1 + 2.5 / np.sqrt(2 * n)
    eff_d = float(np.sqrt(np.mean(z_d**2)))
    eff_c = float(np.sqrt(np.mean(z_c**2) / 2))  # a 2-D error's RMS is sqrt(2) per-axis sigmas
    assert eff_d <= 1.20 * allowance, (eff_d, z_d)
    assert eff_c <= 1.13 * allowance, (eff_c, z_c)
    assert np.abs(z_d).max() <= 4 * 1.20 and z_c.max() <= 4 * 1.13, (z_d, z_c)


def test_no_systematic_diameter_bias(envelope_score):
    # the blur-curvature correction must not leave a bias (uncorrected, a 20 px hole at
    # 2 px blur reads ~0.5 px small)
    assert abs(envelope_score.summary()["mean_diameter_err_px"]) < 0.02


def test_pixel_convention_centre_of_pixel_zero_is_zero():
    """A clean hole at a known sub-pixel centre is found there: renderer and measurer agree.

    A half-pixel slip between the two conventions would show as a 0.5 px error.
    """
    p = FrameParams(width_px=320, height_px=256, groove_depth=0.0, grain=0.0, blotch=0.0, vignetting=0.0,
                    gain_e_per_dn=1e12, read_noise_dn=0.0, blur_sigma_px=1.0)
    for x, y in ((100.0, 120.0), (160.25, 90.75), (200.5, 130.5)):
        f = render_frame(p, [HoleSpec(x, y, 40.0)], seed=0)
        (m,) = measure_holes(f.image)
        assert m.x_px == pytest.approx(x, abs=0.02) and m.y_px == pytest.approx(y, abs=0.02)
        assert m.diameter_px == pytest.approx(40.0, abs=0.03)


def test_blur_correction_inverts_the_bessel_peak_shift():
    """The inversion matches a blurred disc computed independently of its derivation.

    A disc of radius R blurred by an isotropic Gaussian of variance s^2 covers
    P(|X| < R), X ~ N((r, 0), s^2 I), at distance r from its centre: a non-central
    chi-square cdf.  Where its radial slope is steepest is found numerically.
    """
    from scipy.optimize import minimize_scalar
    from scipy.stats import ncx2

    def slope(r, radius, sigma, h=1e-4):
        u = lambda q: ncx2.cdf(radius**2 / sigma**2, 2, q**2 / sigma**2)
        return (u(r + h) - u(r - h)) / (2 * h)  # negative: bright outside -> dark inside

    for radius, sigma in ((10.0, 2.3), (25.0, 1.5), (50.0, 1.0)):
        r_peak = minimize_scalar(lambda r: slope(r, radius, sigma), bounds=(radius - 2 * sigma, radius),
                                 method="bounded", options={"xatol": 1e-7}).x
        assert r_peak < radius - 0.9 * sigma**2 / (2 * radius)  # the shift is real...
        assert deblurred_radius(r_peak, sigma) == pytest.approx(radius, abs=2e-4)  # ...and undone


def test_textured_frames_without_holes_give_no_phantoms():
    found = 0
    for i in range(8):
        rng = np.random.default_rng(500 + i)
        # the roughest walls of the envelope, strong vignetting, noisy sensor
        p = random_params(rng, groove_depth=0.08, grain=0.05, blotch=0.06, vignetting=0.4, gain_e_per_dn=20.0)
        found += len(measure_holes(render_frame(p, [], seed=i).image))
    assert found == 0


def test_holes_cut_by_the_border_are_flagged_partial_and_fitted_on_valid_rays():
    s = Score()
    errs = []
    for i in range(6):
        rng = np.random.default_rng(700 + i)
        p = random_params(rng)
        f = render_frame(p, random_holes(rng, p, n_whole=1, n_partial=2), seed=i)
        ms = measure_holes(f.image)
        s.add(_score(f, ms))
        for h in (h for h in f.holes if h.partial):
            near = [m for m in ms if np.hypot(m.x_px - h.x_px, m.y_px - h.y_px) < 0.25 * h.diameter_px]
            if near:
                errs.append(abs(near[0].diameter_px - h.diameter_px))
    sm = s.summary()
    assert sm["partial_flag_errors"] == 0 and sm["phantoms"] == 0 and sm["misses"] == 0
    assert sm["partial_found"] >= 10  # of 12 cut holes (a thin sliver may stay unmeasured)
    # no edge cut by the border enters the fit (a border edge would pull the diameter
    # by pixels); a 40-85 % arc is noisier than a whole rim: median ~0.15 px
    assert np.median(errs) < 0.25 and max(errs) < 1.0


def test_oval_holes_report_axes():
    p = FrameParams(width_px=320, height_px=256, vignetting=0.0)
    f = render_frame(p, [HoleSpec(160.0, 128.0, 60.0, aspect=1.1, angle_deg=30.0)], seed=1)
    (m,) = measure_holes(f.image)
    a, b = HoleSpec(0, 0, 60.0, aspect=1.1).semi_axes_px
    assert m.major_px == pytest.approx(2 * a, abs=0.3) and m.minor_px == pytest.approx(2 * b, abs=0.3)
    assert m.angle_deg == pytest.approx(30.0, abs=3.0)
    assert m.diameter_px == pytest.approx(60.0, abs=0.2)  # the circle gives the mean diameter


def test_scale_gives_mm():
    p = FrameParams(width_px=320, height_px=256)
    f = render_frame(p, [HoleSpec(160.0, 128.0, 70.0)], seed=2)
    (m,) = measure_holes(f.image, mm_per_px=0.01)
    assert m.diameter_mm == pytest.approx(0.70, abs=0.002)
    (m,) = measure_holes(f.image)
    assert m.diameter_mm is None and "diameter_mm" not in m.to_dict()


# ---------------------------------------------------------------- fits


def test_robust_circle_ignores_outliers_and_taubin_handles_short_arcs():
    rng = np.random.default_rng(0)
    t = rng.uniform(0, np.pi / 2, 200)  # a quarter arc, like a hole cut by a corner
    pts = np.stack([50 + 20 * np.cos(t), 40 + 20 * np.sin(t)], 1) + rng.normal(0, 0.05, (200, 2))
    pts[::5] += rng.uniform(1.0, 4.0, (40, 1))  # 20 % outliers pushed outwards
    inl = ransac_circle(pts, 0.5, rng)
    fit = robust_circle(pts[inl], taubin_circle(pts[inl]))
    assert (fit.cx, fit.cy, fit.r) == pytest.approx((50, 40, 20), abs=0.05)
    full = robust_circle(pts)
    assert full.r == pytest.approx(20, abs=0.05) and full.inliers.sum() <= 170


def test_direct_ellipse_fit_is_exact_on_exact_points():
    t = np.linspace(0, 2 * np.pi, 50, endpoint=False)
    th = np.deg2rad(70)
    x = 10 + 30 * np.cos(t) * np.cos(th) - 20 * np.sin(t) * np.sin(th)
    y = -5 + 30 * np.cos(t) * np.sin(th) + 20 * np.sin(t) * np.cos(th)
    assert fit_ellipse_direct(np.stack([x, y], 1)) == pytest.approx((10, -5, 30, 20, 70), abs=1e-6)


# ---------------------------------------------------------------- photometric refinement


def test_photometric_disc_model_matches_the_exact_blurred_disc():
    """The model's share of a blurred disc (``disc_edge``) against P(|X| < R), X ~ N((rho,
    0), s^2 I), the exact non-central chi-square cdf: its radius and blur, fitted together
    to the exact profile over the annulus the refinement reads, agree with the truth to
    0.0005 px and 0.002 px down to a 6 px radius at 1.5 px of blur and a 10 px radius at
    2.1 px.  The first-order model Phi((R - sqrt(rho^2 + s^2)) / s) (before round 16) is
    fitted here too: on the three small holes it reads the blur 0.015-0.023 px low, more
    than a frame's shared blur is known to (0.006-0.012 px), and the radius 0.002-0.004 px
    low."""
    from scipy.optimize import least_squares
    from scipy.special import ndtr
    from scipy.stats import ncx2

    from station.vision.photometric import disc_fraction

    def first_order(rho, radius, s):
        return ndtr((radius - np.sqrt(rho * rho + s * s)) / s)

    for radius, s in ((6.0, 1.5), (10.0, 2.1), (11.0, 1.93), (25.0, 1.5), (50.0, 0.9)):
        rho = np.linspace(max(radius - 2.5 * s - 1, 0.1), radius + 2.5 * s + 1, 2000)
        exact = ncx2.cdf(radius**2 / s**2, 2, rho**2 / s**2)
        fit = least_squares(lambda p: np.sqrt(rho) * (disc_fraction(rho, p[0], p[1]) - exact), [radius + 0.3, s + 0.1])
        assert fit.x[0] == pytest.approx(radius, abs=5e-4)
        assert fit.x[1] == pytest.approx(s, abs=2e-3)
        old = least_squares(lambda p: np.sqrt(rho) * (first_order(rho, p[0], p[1]) - exact), [radius + 0.3, s + 0.1])
        if radius <= 11.0:
            assert old.x[1] - s < -0.008 and old.x[0] - radius < -0.0015


def test_the_pixels_square_is_in_the_disc_model():
    """The camera blurs the scene, then each pixel integrates its square.  The model's
    Gaussian of s^2 = blur^2 + 1/12 holds the square's variance; ``pixel_box_term`` adds
    its fourth cumulant.  Against the exact disc (x) Gaussian (x) pixel over a 60 px hole's
    edge, the model with the term is within 1.5e-5 of the step (RMS; measured 1.1e-5 at
    0.8 px of blur, 3.6e-6 at 1 px), without it 12-15 times further (1.3e-4, 5.6e-5): an
    odd ripple that a grain-aware fit,
    whose covariance differs on the two sides of the rim, read as a diameter 0.001 px
    short (docs/vision-history.md, round 17)."""
    from scipy.special import ndtr

    from edge_physics import exact_pixel_share
    from station.vision.photometric import disc_edge, pixel_box_term

    for blur in (0.8, 1.0):
        yy, xx = np.mgrid[0:200, 0:200].astype(float)
        ex, ey = xx - 100.3, yy - 99.6
        rho = np.hypot(ex, ey)
        band = np.abs(rho - 30.0) < 4 * blur + 1
        exact = exact_pixel_share(xx[band], yy[band], 100.3, 99.6, 30.0, blur)
        m, v, _, _ = disc_edge(rho[band], float(np.sqrt(blur**2 + 1 / 12)))
        t = (30.0 - m) / v
        gauss = ndtr(t)
        boxed = gauss + pixel_box_term(t, v, ex[band] / rho[band], ey[band] / rho[band])
        with_term, without = np.sqrt(np.mean((boxed - exact) ** 2)), np.sqrt(np.mean((gauss - exact) ** 2))
        assert with_term < 1.5e-5
        assert without > 4 * with_term


def test_photometric_refinement_on_clean_and_grooved_holes():
    """Clean frames: the refined diameter within 0.03 px (observed -0.025 px on a 24 px
    hole at 2 px blur, the largest model error found).  Grooved walls: within 0.1 px
    of the truth on every hole and not worse on average than the ray edges alone."""
    from station.vision.measure import MeasureConfig
    from station.vision.photometric import PhotometricConfig

    cfg = MeasureConfig(photometric=PhotometricConfig())
    rays_only = MeasureConfig(photometric=None)
    clean = FrameParams(width_px=320, height_px=256, groove_depth=0.0, grain=0.0, blotch=0.0, vignetting=0.3,
                        gain_e_per_dn=1e12, read_noise_dn=0.0)
    for d, blur in ((24.0, 2.0), (60.0, 1.2), (96.0, 0.8)):
        f = render_frame(replace(clean, blur_sigma_px=blur), [HoleSpec(161.3, 127.6, d)], seed=0)
        (m,) = measure_holes(f.image, cfg=cfg)
        assert m.diameter_px == pytest.approx(d, abs=0.03)
    err_ph, err_rays = [], []
    for i in range(6):
        rng = np.random.default_rng(900 + i)
        p = random_params(rng, groove_depth=0.08)  # the roughest walls of the envelope
        f = render_frame(p, random_holes(rng, p, n_whole=3), seed=i)
        for c, errs in ((cfg, err_ph), (rays_only, err_rays)):
            s = _score(f, measure_holes(f.image, cfg=c)).summary()
            assert s["misses"] == 0 and s["phantoms"] == 0
            errs += list(np.abs(_score(f, measure_holes(f.image, cfg=c)).diameter_err_px))
    assert max(err_ph) < 0.1
    assert np.mean(err_ph) <= np.mean(err_rays) + 0.005


def test_the_grooves_cut_by_the_hole_before_the_blur_are_modelled():
    """Grooves only (no grain, no sensor noise, 8 % deep): the term for a groove cut by
    the hole before the blur (B[G (1 - c)] - B[G] (1 - B[c])) must take out part of the
    grooves' error (observed: mean |error| 0.0127 -> 0.0100 px, worst 0.059 -> 0.040 px
    on these 36 holes)."""
    from station.vision.photometric import PhotometricConfig

    frames = [random_frame(500 + i, n_whole=3, n_partial=0, grain=0.0, blotch=0.0, groove_depth=0.08,
                           read_noise_dn=0.0, gain_e_per_dn=1e9) for i in range(12)]

    def mean_abs(cut: bool) -> float:
        cfg = MeasureConfig(photometric=PhotometricConfig(groove_cut_term=cut))
        errs = []
        for f in frames:
            s = _score(f, measure_holes(f.image, cfg=cfg))
            assert s.summary()["misses"] == 0
            errs += list(np.abs(s.diameter_err_px))
        return float(np.mean(errs))

    with_term, without = mean_abs(True), mean_abs(False)
    assert with_term < 0.9 * without


@pytest.mark.parametrize("slope_dn_per_px", [0.5, -0.5])
def test_the_walls_radial_slope_is_read_from_the_ring(slope_dn_per_px):
    """A wall that brightens (or darkens) by 0.5 DN per px away from a 40 px hole at
    1.8 px blur: the rim's edge moves by the slope's share of the blur (B[W (1 - c)] for
    a sloped W), which the annulus cannot tell from the radius.  Without the ring's
    slope the diameter reads ~0.10 px off (observed +0.104 / -0.099 px over these 10
    frames, noise 0.05 px each); with the ring's Fourier slope at full size the bias is
    gone (+0.000 / +0.002), shrunk by half (round 14's default) half of it is left.  The
    default since round 15, a 2-D polynomial of the ring carried in to the rim, leaves
    about a quarter (+0.026 / -0.027 px): a quadratic's radial slope grows with the
    radius, a cone's does not, and blotches are smooth fields, not cones.  Since session
    41 the hole's level follows the frame illumination's curvature, and this frame-wide
    cone is what its quadratic then reads as illumination: every variant reads 0.017-0.019
    px further out (none +0.125, full +0.016, half +0.071, the default +0.044 px), the
    price of a world whose wall reflectance, not its light, shapes the whole frame."""
    from station.vision.photometric import PhotometricConfig

    p = FrameParams(width_px=320, height_px=256, groove_depth=0.0, grain=0.0, blotch=0.0, vignetting=0.0,
                    blur_sigma_px=1.8, wall_level_dn=150.0, hole_level_dn=80.0, gain_e_per_dn=40.0)
    yy, xx = np.mgrid[0:256, 0:320]
    frames = []
    for k in range(10):
        cx, cy = 160.3 + 0.1 * k, 127.7 - 0.07 * k
        wall = (150.0 + slope_dn_per_px * (np.hypot(xx - cx, yy - cy) - 20.0)).astype(np.float32)
        frames.append(render_frame(p, [HoleSpec(cx, cy, 40.0)], seed=k, wall=wall))

    def bias(shrink: float, poly: int = 0) -> float:
        cfg = MeasureConfig(photometric=PhotometricConfig(ring_slope_shrink=shrink, ring_slope_poly=poly))
        errs = []
        for f in frames:
            (m,) = measure_holes(f.image, cfg=cfg)
            errs.append(m.diameter_px - f.holes[0].diameter_px)
        return float(np.mean(errs))

    sign = np.sign(slope_dn_per_px)
    d = PhotometricConfig()
    none, full, half = bias(0.0), bias(1.0), bias(0.5)
    default = bias(d.ring_slope_shrink, d.ring_slope_poly)
    assert sign * none > 0.06
    assert abs(full) < 0.025
    assert 0.3 * sign * none < sign * half < 0.7 * sign * none
    assert 0.1 * sign * none < sign * default < 0.4 * sign * none


def test_the_holes_level_follows_the_illuminations_curvature():
    """Vignetting multiplies the hole's dark far side as it does the wall: on a 640 x 480
    frame at 50 % vignetting the far side of a 100 px hole is ~0.9 % darker at its rim
    than at its centre.  A hole level that is constant over the inside (flat-fielded by
    the illumination's local gradient only) reads the darker rim as more hole: the
    diameter +0.024 px over these 12 frames (noise 0.008 px each).  With the hole's level
    following the frame illumination's quadratic (``PhotometricConfig.
    hole_illumination_curvature``) +0.005 px.  The wall's own curvature is the ring's
    (its reflectance varies; the hole's far side does not)."""
    from station.vision.photometric import PhotometricConfig

    p = FrameParams(width_px=640, height_px=480, groove_depth=0.0, grain=0.0, blotch=0.0, vignetting=0.5,
                    blur_sigma_px=1.0, wall_level_dn=150.0, hole_level_dn=90.0, gain_e_per_dn=40.0)
    frames = [render_frame(p, [HoleSpec(150.3 + 0.1 * k, 140.7 - 0.07 * k, 100.0)], seed=k) for k in range(12)]

    def bias(on: bool) -> float:
        cfg = MeasureConfig(photometric=PhotometricConfig(hole_illumination_curvature=on))
        errs = []
        for f in frames:
            (m,) = measure_holes(f.image, cfg=cfg)
            errs.append(m.diameter_px - f.holes[0].diameter_px)
        return float(np.mean(errs))

    flat, curved = bias(False), bias(True)
    assert flat > 0.015
    assert abs(curved) < 0.4 * flat
    assert PhotometricConfig().hole_illumination_curvature


# ---------------------------------------------------------------- blur correction, fits, helpers


@pytest.mark.parametrize("contrast", [0.4, 0.85])
def test_blur_correction_recovers_known_diameters_on_clean_frames(contrast):
    """Texture- and noise-free holes of 20-100 px at 0.8-2 px blur: the measured width
    of the rim and the Bessel inversion give the diameter within 0.015 px (observed
    <= 0.0092 px on this grid).  Without the correction the same holes read up to
    ~0.5 px small (20 px at 2 px blur), so the bound is far from what a broken or
    missing correction gives."""
    clean = FrameParams(width_px=320, height_px=256, groove_depth=0.0, grain=0.0, blotch=0.0, vignetting=0.0,
                        gain_e_per_dn=1e12, read_noise_dn=0.0)
    for d in (20.0, 30.0, 50.0, 100.0):
        for blur in (0.8, 1.4, 2.0):
            p = replace(clean, blur_sigma_px=blur, hole_level_dn=clean.wall_level_dn * (1 - contrast))
            f = render_frame(p, [HoleSpec(160.37, 127.71, d)], seed=0)
            # the rays' diameter (the photometric refinement, on by default, has its own
            # model and its own test)
            (m,) = measure_holes(f.image, cfg=MeasureConfig(photometric=None))
            assert m.diameter_px == pytest.approx(d, abs=0.015), (d, blur)
            assert m.edge_sigma_px > blur  # the measured width holds the camera blur


def test_default_pipeline_refines_whole_holes_photometrically_and_leaves_cut_holes_to_the_rays():
    """The photometric fit is on by default: a whole hole's diameter is the fit's, its
    centre the mean of the rays' and the fit's (a small move); a cut hole is exactly the
    rays-only pipeline's."""
    from station.vision.measure import MeasureConfig

    assert MeasureConfig().photometric is not None
    rng = np.random.default_rng(77)
    p = random_params(rng)
    f = render_frame(p, random_holes(rng, p, n_whole=3, n_partial=1), seed=5)
    ours, rays = measure_holes(f.image), measure_holes(f.image, cfg=MeasureConfig(photometric=None))
    assert len(ours) == len(rays) == 4
    for a, b in zip(ours, rays):
        assert a.partial == b.partial
        if a.partial:
            assert (a.x_px, a.y_px, a.diameter_px) == (b.x_px, b.y_px, b.diameter_px)
        else:
            assert a.diameter_px != b.diameter_px and abs(a.diameter_px - b.diameter_px) < 0.2
            assert (a.x_px, a.y_px) != (b.x_px, b.y_px) and np.hypot(a.x_px - b.x_px, a.y_px - b.y_px) < 0.1


def test_median_helper_equals_numpy_median():
    from station.vision.fit import median

    rng = np.random.default_rng(3)
    for n in (1, 2, 5, 6, 101, 400):
        a = rng.normal(size=n)
        assert median(a) == np.median(a)
    assert median(np.array([[3.0, 1.0], [2.0, 4.0]])) == 2.5


def test_oval_circle_fit_gives_centre_and_mean_radius_of_a_slight_ellipse():
    # semi-axes 20.2 / 19.8 at 25 deg: the second harmonic absorbs the ovality, r is the
    # mean radius to second order in the ovality ((a-b)/(a+b))^2 r = 0.002 px
    t = np.linspace(0, 2 * np.pi, 180, endpoint=False)
    th = np.deg2rad(25)
    x = 50 + 20.2 * np.cos(t) * np.cos(th) - 19.8 * np.sin(t) * np.sin(th)
    y = 40 + 20.2 * np.cos(t) * np.sin(th) + 19.8 * np.sin(t) * np.cos(th)
    pts = np.stack([x, y], 1)
    oval = robust_circle(pts, (50.3, 39.8, 19.0), oval=True)
    assert (oval.cx, oval.cy, oval.r) == pytest.approx((50, 40, 20), abs=0.005)
    assert oval.rms_px < 0.01 and oval.inliers.all()
    plain = robust_circle(pts, (50.3, 39.8, 19.0))  # without the harmonic the extremes are residuals
    assert plain.rms_px > 0.1


def test_rims_smaller_than_the_hole_envelope_are_refused():
    """A 17 px dark disc is measured when the floor is lowered, and refused at the
    default floor (90 % of the smallest hole, 20 px); a 20 px hole is kept."""
    from station.vision.measure import MeasureConfig

    assert MeasureConfig().min_diameter_px == pytest.approx(18.0)
    p = FrameParams(width_px=320, height_px=256, groove_depth=0.0, grain=0.01, blotch=0.0, vignetting=0.0,
                    blur_sigma_px=1.2)
    small = render_frame(p, [HoleSpec(160.2, 127.7, 17.0)], seed=4)
    (m,) = measure_holes(small.image, cfg=MeasureConfig(min_diameter_px=16.0))
    assert m.diameter_px == pytest.approx(17.0, abs=0.1)
    assert measure_holes(small.image) == []
    (m,) = measure_holes(render_frame(p, [HoleSpec(160.2, 127.7, 20.0)], seed=4).image)
    assert m.diameter_px == pytest.approx(20.0, abs=0.1)


def test_holes_are_judged_on_their_relative_contrast():
    """A through-hole is dark: a candidate is refused when it is less than
    ``min_relative_contrast`` darker than the wall just outside it (crossing honing
    grooves that pass the shape tests measure 0.10-0.22), however good its shape.  A
    hole of 30 % contrast (a fluid film in it) is measured at the default bar."""
    from station.vision.measure import MeasureConfig, relative_contrast

    assert 0.15 <= MeasureConfig().min_relative_contrast <= 0.25
    base = FrameParams(width_px=320, height_px=256, groove_depth=0.0, grain=0.01, blotch=0.0, vignetting=0.2,
                       blur_sigma_px=1.5)
    for contrast in (0.20, 0.30):
        p = replace(base, hole_level_dn=base.wall_level_dn * (1 - contrast))
        f = render_frame(p, [HoleSpec(160.2, 127.7, 24.0)], seed=3)
        assert relative_contrast(f.image, 160.2, 127.7, 12.0, 1.5) == pytest.approx(contrast, abs=0.03)
        (m,) = measure_holes(f.image, cfg=MeasureConfig(min_relative_contrast=contrast - 0.05))
        assert m.diameter_px == pytest.approx(24.0, abs=0.1)
        assert measure_holes(f.image, cfg=MeasureConfig(min_relative_contrast=contrast + 0.05)) == []
    (m,) = measure_holes(f.image)  # the 30 % hole at the default bar
    assert m.diameter_px == pytest.approx(24.0, abs=0.1)


def test_warm_up_measures_its_synthetic_hole():
    """The station loads the compiled kernels before its first inspection by measuring a
    synthetic hole: it must find exactly that hole, or the warm-up exercised nothing."""
    from station.vision.measure import warm_up

    assert warm_up() == 1


def test_a_centre_that_ran_off_the_frame_gives_no_edges_not_an_opencv_error():
    # a refinement that diverged far past the border left an empty region of interest,
    # and OpenCV refused it ("!_src.empty()"): the inspection faulted instead of the
    # candidate being rejected as cut by the border
    from station.vision.measure import _fine

    image = np.full((256, 320), 120, np.uint8)
    for cx, cy in ((-500.0, 100.0), (100.0, 900.0), (1e4, -1e4)):
        edges = _fine(image, cx, cy, 20.0, 40.0, 72)
        assert edges.points.shape == (0, 2) and edges.cut_by_border
    # one just inside still reads its edges
    yy, xx = np.mgrid[0:256, 0:320]
    image[(xx - 160) ** 2 + (yy - 128) ** 2 < 30**2] = 20
    assert len(_fine(image, 160.0, 128.0, 20.0, 40.0, 72).points) > 60


# ---------------------------------------------------------------- the hatch's angle
@pytest.mark.parametrize("angle", [22.0, 25.0, 35.0])
def test_the_frames_hatch_directions_are_read_to_a_tenth_of_a_degree(angle):
    """The honing angle is the part's (plateau honing: 20-35 deg), not the station's."""
    from station.vision.grooves import frame_hatch

    for seed in (3000, 3001):
        f = random_frame(seed, hatch_deg=angle)
        a1, a2 = frame_hatch(f.image, [(h.x_px, h.y_px, 1.3 * h.diameter_px / 2 + 4.0) for h in f.holes])
        assert a1 == pytest.approx(angle, abs=0.1) and a2 == pytest.approx(-angle, abs=0.1)


def test_a_frame_without_a_hatch_keeps_the_nominal_directions():
    from station.vision.grooves import frame_hatch

    p = FrameParams(groove_depth=0.0, width_px=640, height_px=512)
    f = render_frame(p, [HoleSpec(320.3, 256.6, 70.0)], seed=4)
    assert frame_hatch(f.image, [(320.3, 256.6, 50.0)], (28.0, -31.0)) == (28.0, -31.0)


def test_holes_on_a_25_degree_hatch_are_measured_with_the_hatch_the_frame_shows():
    """A 25 deg hatch (8 % grooves) read as the nominal 30 deg leaves the grooves in the
    rim's pixels; read from the frame it is modelled (dev seeds: diameter z^2 +0.33 to
    +0.50 with the nominal, +0.003 to +0.006 against the true angle read)."""
    from station.vision.scoring import match_whole_holes

    errors = {True: [], False: []}
    for seed in range(7100, 7112):
        f = random_frame(seed, groove_depth=0.08, hatch_deg=25.0)
        truths = [(h.x_px, h.y_px, h.diameter_px, h.partial) for h in f.holes]
        whole = [t for t in truths if not t[3]]
        for read in (True, False):
            found = measure_holes(f.image, cfg=MeasureConfig(read_hatch=read))
            det = [(m.x_px, m.y_px, m.diameter_px, m.partial) for m in found]
            for t, j in zip(whole, match_whole_holes(truths, det)):
                assert j is not None
                errors[read].append(found[j].diameter_px - t[2])
    rms = {k: float(np.sqrt(np.mean(np.square(v)))) for k, v in errors.items()}
    assert len(errors[True]) >= 20
    assert rms[True] < 0.85 * rms[False], rms


def test_a_candidate_with_no_agreeing_ray_is_no_hole_under_relaxed_gates():
    """With the rays' gates relaxed to nothing (``MeasureConfig`` is the user's), a dark
    blob whose rays agree on no circle (wide bench frame 1300047: a 0.48 mm pore) has no
    inlier profile to read its edge width from: the candidate is no hole, where the
    contrast's read of a NaN width raised."""
    from sim.camera.defects import random_defect_frame
    from station.vision.detect import detect_candidates, for_scale
    from station.vision.measure import _ray_stage

    f = random_defect_frame(1300047, None, mm_per_px=0.01, envelope="wide")
    cfg = MeasureConfig(photometric=None, min_inlier_fraction=0.0, min_coverage=0.0, min_relative_contrast=0.0)
    cfg = replace(cfg, detect=for_scale(cfg.detect, 0.01))
    (cand,) = [c for c in detect_candidates(f.image, cfg.detect) if abs(c.x_px - 881) < 3 and abs(c.y_px - 619) < 3]
    assert _ray_stage(f.image, cand, cfg) is None
