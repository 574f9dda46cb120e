"""The grain-aware (GLS) step of the photometric fit: its noise model and its solver."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from scipy.ndimage import gaussian_filter

from station.vision.gls import GrainNoise, NoiseOperator, estimate_noise


def _grain_field(rng, shape, corr, s_cam, grain_var, sensor_var):
    """White grain through a Gaussian of ``corr`` and the camera's ``s_cam``, scaled to
    ``grain_var`` per pixel, plus white sensor noise of ``sensor_var``."""
    g = gaussian_filter(rng.standard_normal(shape), corr)
    g = gaussian_filter(g, s_cam)
    g *= np.sqrt(grain_var) / g.std()
    return g + np.sqrt(sensor_var) * rng.standard_normal(shape)


def test_the_wall_residuals_split_into_sensor_and_grain():
    rng = np.random.default_rng(5)
    for corr, s_cam, gv, sv in ((0.7, 1.0, 12.0, 6.0), (0.7, 1.6, 3.0, 5.0), (1.0, 1.2, 8.0, 2.0)):
        field = _grain_field(rng, (160, 160), corr, s_cam, gv, sv)
        ok = np.ones(field.shape, bool)
        ok[60:100, 60:100] = False  # a hole's place: no wall there
        n = estimate_noise(field, ok, inner_var=sv, s_cam=s_cam)
        assert n is not None
        assert abs(n.grain_var - gv) / gv < 0.25, (corr, s_cam, n)
        assert abs(n.sensor_out_var - sv) / sv < 0.35, (corr, s_cam, n)
        assert abs(n.corr_px - corr) < 0.45, (corr, s_cam, n)


def test_white_wall_residuals_carry_no_grain():
    rng = np.random.default_rng(6)
    field = 2.0 * rng.standard_normal((120, 120))
    n = estimate_noise(field, np.ones(field.shape, bool), inner_var=4.0, s_cam=1.2)
    assert n.grain_var < 0.1 * 4.0
    assert abs(n.sensor_out_var - 4.0) < 0.4


def test_a_wall_without_noise_still_has_the_quantisations():
    """A noise-free wall (a synthetic frame) leaves residuals of ~0: its pixels' variance is
    floored at the 8-bit quantisation's 1/12 DN^2 and a quarter of the hole side's, never 0
    (it read 3e-8 DN^2 once, and a noise-free hole's grain-aware step moved 0.18 px)."""
    for field in (np.zeros((60, 60)), 1e-4 * np.random.default_rng(7).standard_normal((60, 60))):
        n = estimate_noise(field, np.ones(field.shape, bool), inner_var=0.25, s_cam=1.0)
        assert n.sensor_out_var >= 1.0 / 12.0
    assert estimate_noise(np.zeros((60, 60)), np.ones((60, 60), bool), inner_var=4.0, s_cam=1.0).sensor_out_var == 1.0


def test_too_little_wall_gives_no_noise_model():
    assert estimate_noise(np.zeros((10, 10)), np.ones((10, 10), bool), 1.0, 1.0) is None


def test_the_solver_inverts_the_dense_covariance():
    """C^-1 b by conjugate gradients equals a dense solve of the same C (built column by
    column from the operator), on a patch with a hole's cut and pixels left out."""
    h = w = 17
    yy, xx = np.mgrid[0:h, 0:w]
    rho = np.hypot(xx - 8.2, yy - 7.9)
    wall_share = np.clip(rho - 4.5, 0.0, 1.0)
    sel = rho < 8.5
    op = NoiseOperator(GrainNoise(2.0, 3.0, 5.0, 0.7), sel, wall_share, 1.1)
    idx = np.flatnonzero(sel)
    cols = []
    for i in idx:
        e = np.zeros((1, h, w))
        e.flat[i] = 1.0
        cols.append(op.apply(e)[0].ravel()[idx])
    dense = np.array(cols).T
    assert np.allclose(dense, dense.T, atol=1e-6)  # a covariance is symmetric ...
    assert np.linalg.eigvalsh(dense).min() > 0  # ... and positive definite
    rng = np.random.default_rng(7)
    b = np.zeros((2, h, w))
    b[:, sel] = rng.standard_normal((2, idx.size))
    x = op.solve(b, tol=1e-8, max_iter=500)
    for k in range(2):
        ref = np.linalg.solve(dense, b[k].ravel()[idx])
        # the operator blurs in float32: agreement to ~1e-6 of the solution's size
        assert np.allclose(x[k].ravel()[idx], ref, rtol=0, atol=1e-5 * np.abs(ref).max())
        assert np.all(x[k][~sel] == 0.0)


def test_a_gls_step_keeps_the_hole_and_reports_its_covariance():
    """On a rendered grain-heavy hole the covariance-weighted step stays on the hole and
    its uncertainty is the inverse normal matrix: finite, and of the size of the bound."""
    from sim.camera.render import FrameParams, HoleSpec, render_frame
    from station.vision.photometric import PhotometricConfig, refine_hole

    p = FrameParams(wall_level_dn=150.0, hole_level_dn=60.0, groove_depth=0.0, grain=0.05, blotch=0.0,
                    blur_sigma_px=1.1, gain_e_per_dn=30.0, read_noise_dn=1.0, vignetting=0.0)
    hole = HoleSpec(400.3, 300.6, 60.0)
    cfg = dataclasses.replace(PhotometricConfig(), gls_steps=1)
    errs, us = [], []
    for seed in range(4):
        f = render_frame(p, [hole], seed=seed)
        fit = refine_hole(f.image.astype(np.float64), 400.0, 301.0, 29.8, 1.15, cfg)
        assert fit is not None and fit.converged
        errs.append(2 * fit.r - 60.0)
        us.append(2 * fit.r_u)
    assert np.all(np.isfinite(us)) and min(us) > 0.005 and max(us) < 0.08, us
    assert max(abs(e) for e in errs) < 0.15, errs


def test_the_gls_step_beats_the_weighted_fit_on_grain_and_knows_its_scatter():
    """60 renders of one hole on a grain-heavy wall (4 %, blur 1.0 px: where a weighted
    fit is furthest from the bound), fresh grain and noise each, the blur held as the
    frame's shared blur holds it: the grain-aware step's radius scatters less than the
    weighted fit's, and its uncertainty (the inverse normal matrix scaled by the
    chi-square) is the scatter's size."""
    from sim.camera.render import FrameParams, HoleSpec, render_frame
    from station.vision.photometric import PhotometricConfig, refine_hole

    r, s = 16.0, 1.0
    hole = HoleSpec(80.3, 79.8, 2 * r)
    params = FrameParams(width_px=160, height_px=160, wall_level_dn=150, hole_level_dn=60, grain=0.04,
                         groove_depth=0.0, blotch=0.0, blur_sigma_px=s, gain_e_per_dn=30, read_noise_dn=1.5,
                         vignetting=0.0)
    w_cfg = dataclasses.replace(PhotometricConfig(), fit_blur=False)
    gls_cfg = dataclasses.replace(w_cfg, gls_steps=1)
    e_w, e_g, u_g = [], [], []
    for seed in range(60):
        img = render_frame(params, [hole], seed=seed).image
        start = (80.3, 79.8, r, float(np.hypot(s, 0.29)))
        w = refine_hole(img, *start, cfg=w_cfg)
        g = refine_hole(img, *start, cfg=gls_cfg)
        assert w.converged and g.converged and g.gls and not w.gls
        e_w.append(w.r - r)
        e_g.append(g.r - r)
        u_g.append(g.r_u)
    sd_w, sd_g, u = float(np.std(e_w)), float(np.std(e_g)), float(np.median(u_g))
    assert sd_g < 0.95 * sd_w, (sd_g, sd_w)
    assert 0.75 < u / sd_g < 1.3, (u, sd_g)


def test_a_held_blur_reports_how_the_hole_moves_with_it():
    """With the blur held (the frame's shared blur), the fit reports d(R0, cx, cy)/d(blur):
    refitting with the blur held 0.005 px higher or lower moves the radius by that much
    (weighted and grain-aware steps alike; 0.47 and 0.58 px per px here, so a frame blur
    known to 0.007 px adds 0.004 px to the radius's error); the centre, on a round
    hole's symmetry, barely moves. A free blur reports none: it is in the fit's own
    uncertainty."""
    from sim.camera.render import FrameParams, HoleSpec, render_frame
    from station.vision.photometric import PhotometricConfig, refine_hole

    p = FrameParams(width_px=200, height_px=200, wall_level_dn=150.0, hole_level_dn=50.0, groove_depth=0.05,
                    grain=0.02, blotch=0.0, blur_sigma_px=1.3, gain_e_per_dn=30.0, read_noise_dn=1.0,
                    vignetting=0.0)
    hole = HoleSpec(100.4, 99.7, 36.0, aspect=1.02, angle_deg=20.0)
    img = render_frame(p, [hole], seed=3).image.astype(np.float64)
    s = float(np.hypot(1.3, 0.29))
    for steps in (0, 1):
        cfg = dataclasses.replace(PhotometricConfig(), fit_blur=False, gls_steps=steps)
        a = refine_hole(img, 100.0, 100.0, 18.1, s, cfg)
        assert a.converged and a.gls == bool(steps)
        assert np.isfinite([a.r_ds, a.cx_ds, a.cy_ds]).all()
        assert abs(a.r_ds) > 0.2  # the blur and the radius are coupled
        for d in (-0.005, 0.005):
            b = refine_hole(img, 100.0, 100.0, 18.1, s + d, cfg)
            assert (b.r - a.r) / d == pytest.approx(a.r_ds, rel=0.05)
            assert max(abs(b.cx - a.cx), abs(b.cy - a.cy)) / 0.005 < 0.2 * abs(a.r_ds)
        assert max(abs(a.cx_ds), abs(a.cy_ds)) < 0.2 * abs(a.r_ds)
    free = refine_hole(img, 100.0, 100.0, 18.1, s, dataclasses.replace(PhotometricConfig(), gls_steps=1))
    assert free.converged and np.isnan(free.r_ds)
