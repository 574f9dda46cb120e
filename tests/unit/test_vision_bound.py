"""The Cramer-Rao bound of a hole's diameter (station bench vision-bound).

The bound is only worth quoting if (1) its matrix-free solve is the dense one, and
(2) it is what an efficient estimator really reaches on the renderer's frames: not
a factor off in either direction.
"""

import numpy as np
import pytest

from sim.camera.render import FrameParams, HoleSpec, render_frame
from station.bench.vision_bound import HoleCase, _Geometry, attainability, diameter_bound_px, fisher
from station.vision.photometric import PhotometricConfig, refine_hole


def _dense_fisher(case: HoleCase) -> np.ndarray:
    geo = _Geometry(case, blur_known=False, with_grain=True)
    p, h, w = geo.jac.shape
    n = h * w
    eye = np.eye(n).reshape(n, h, w)
    cov = np.concatenate([geo.apply_cov(eye[i:i + 256]) for i in range(0, n, 256)]).reshape(n, n)
    assert np.abs(cov - cov.T).max() < 1e-9 * np.abs(cov).max()  # a covariance is symmetric
    assert np.linalg.eigvalsh(cov).min() > 0
    j = geo.jac.reshape(p, n)
    return j @ np.linalg.solve(cov, j.T)


def test_matrix_free_fisher_equals_the_dense_computation():
    case = HoleCase(radius_px=7.0, blur_px=1.3, wall_dn=150, hole_dn=55, grain=0.04, gain_e_per_dn=30,
                    read_noise_dn=2.0, vignetting_gain=0.85, frac_x=0.31, frac_y=-0.22)
    dense = _dense_fisher(case)
    f, names = fisher(case)
    assert names[0] == "R"
    assert np.abs(f - dense).max() <= 1e-7 * np.abs(dense).max()


def test_grain_an_unknown_blur_and_an_unknown_wall_slope_cost_information():
    case = HoleCase(radius_px=20.0, blur_px=1.5, wall_dn=150, hole_dn=60, grain=0.03, gain_e_per_dn=40,
                    read_noise_dn=1.5)
    sensor = diameter_bound_px(case, with_grain=False)
    grain = diameter_bound_px(case)
    known = diameter_bound_px(case, blur_known=True)
    assert sensor < known < grain
    # a wall slope known from outside the annulus: less to estimate, a tighter bound
    assert diameter_bound_px(case, slope_order=-1) < 0.97 * grain
    # a hole twice as large has twice the rim: about 1/sqrt(2) of the scatter
    big = diameter_bound_px(HoleCase(**{**case.__dict__, "radius_px": 40.0}), with_grain=False)
    assert 0.55 < big / sensor < 0.85


def test_predicted_median_of_equal_sigmas_is_the_half_normal_median():
    a = attainability(np.full(201, 0.02), np.tile(0.02**2 * np.eye(2), (201, 1, 1)), draws=2000)
    assert a["predicted_median_abs_diameter_err_px"] == pytest.approx(0.6745 * 0.02, rel=0.03)
    # the half-normal's 90th percentile is 1.645 sigma
    assert a["predicted_p90_abs_diameter_err_px"] == pytest.approx(1.645 * 0.02, rel=0.03)


def test_the_bound_is_what_a_least_squares_fit_reaches_on_rendered_frames():
    """Monte Carlo: 100 renders of one hole with fresh sensor noise (no texture), the
    photometric fit with the same nuisance parameters as the bound (wall Fourier order
    4, no radial slope, blur fitted, plain least squares): its scatter must be at or
    a little above the bound (an efficient estimator), never far below (a wrong bound)."""
    r, s = 18.0, 1.4
    params = FrameParams(width_px=160, height_px=160, wall_level_dn=150, hole_level_dn=60, grain=0.0,
                         groove_depth=0.0, blotch=0.0, blur_sigma_px=s, gain_e_per_dn=40, read_noise_dn=1.5,
                         vignetting=0.0)
    hole = HoleSpec(80.3, 79.8, 2 * r)
    cfg = PhotometricConfig(k_sigma=3.0, pad_px=3.0, groove_angles_deg=None, huber_k=100.0, iterations=5)
    errs = []
    for seed in range(100):
        fit = refine_hole(render_frame(params, [hole], seed=seed).image, 80.3, 79.8, r, np.hypot(s, 0.29), cfg)
        errs.append(2 * fit.r - 2 * r)
    case = HoleCase(r, s, 150, 60, 0.0, 40, 1.5, frac_x=0.3, frac_y=-0.2)
    bound = diameter_bound_px(case, with_grain=False, slope_order=-1)
    ratio = float(np.std(errs)) / bound
    assert 0.8 < ratio < 1.5, (np.std(errs), bound)


def test_attainability_matches_the_closed_form_for_equal_holes():
    """n holes with the same Gaussian errors: P(worst |d| <= bar) = (2 Phi(bar / sigma) - 1)^n
    and P(worst centre <= bar) = (1 - exp(-bar^2 / 2 sigma_c^2))^n (Rayleigh)."""
    from scipy.special import ndtr

    n, sd, sc = 300, 0.05, 0.035
    a = attainability(np.full(n, sd), np.tile(sc**2 * np.eye(2), (n, 1, 1)), draws=4000)
    p_d = (2 * ndtr(0.15 / sd) - 1) ** n
    p_c = (1 - np.exp(-0.1**2 / (2 * sc**2))) ** n
    assert a["p_worst_diameter_within_bar"] == pytest.approx(p_d, abs=0.03)
    assert a["p_worst_centre_within_bar"] == pytest.approx(p_c, abs=0.03)
    assert a["expected_holes_over_diameter_bar"] == pytest.approx(n * 2 * ndtr(-3.0), rel=1e-9)
    assert a["expected_holes_over_centre_bar"] == pytest.approx(n * np.exp(-0.1**2 / (2 * sc**2)), rel=0.05)
    assert a["predicted_median_abs_diameter_err_px"] == pytest.approx(0.6745 * sd, rel=0.03)
    assert a["predicted_median_centre_err_px"] == pytest.approx(np.sqrt(2 * np.log(2)) * sc, rel=0.03)


def test_centre_covariance_comes_from_the_same_fisher_matrix():
    from station.bench.vision_bound import hole_bound

    case = HoleCase(radius_px=15.0, blur_px=1.2, wall_dn=150, hole_dn=60, grain=0.03, gain_e_per_dn=40,
                    read_noise_dn=1.5)
    d_sigma, c_cov = hole_bound(case)
    assert d_sigma == pytest.approx(diameter_bound_px(case))
    # a round hole: the same scatter in x and y, no correlation
    assert c_cov[0, 0] == pytest.approx(c_cov[1, 1], rel=0.1)
    assert abs(c_cov[0, 1]) < 0.1 * c_cov[0, 0]
    # N rim points with independent radial errors e: var R = e^2 / N, var cx = 2 e^2 / N,
    # so sigma_cx = sqrt(2) sigma_R when the blur is known and the noise is white (the
    # wall's first harmonic, a nuisance, costs the centre a little more)
    d_white, c_white = hole_bound(case, blur_known=True, with_grain=False)
    assert np.sqrt(c_white[0, 0]) / (d_white / 2) == pytest.approx(np.sqrt(2), rel=0.12)


def test_bound_bench_compares_median_and_tail_with_hough_on_the_same_frames():
    from station.bench.vision_bound import run

    r = run(frames=1, seed=1002, baseline=True)  # one frame, three whole holes
    assert r["whole_holes"] == 3
    b = r["bounds"]["blur_free"]
    assert b["best_diameter_ratio_vs_hough_alt"] == pytest.approx(
        r["hough_alt_median_diameter_err_px"] / b["predicted_median_abs_diameter_err_px"])
    assert b["best_diameter_ratio_vs_hough_alt_p90"] == pytest.approx(
        r["hough_alt_p90_diameter_err_px"] / b["predicted_p90_abs_diameter_err_px"])
    # the set's 90th percentile of |error| lies above its median
    assert b["predicted_p90_abs_diameter_err_px"] > b["predicted_median_abs_diameter_err_px"]


def test_bound_bench_refuses_frames_without_a_whole_hole():
    from station.bench.vision_bound import run

    with pytest.raises(ValueError, match="no whole hole"):
        run(frames=2, seed=1000)
