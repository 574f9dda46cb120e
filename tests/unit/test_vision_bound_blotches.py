"""The bound with the wall's blotches as a random field (``--blotches``).

The criteria's bound (``frame_aware_grooves``) leaves the blotches to the wall's Fourier
series and its linear radial slope: a blotch's curvature at the rim is no nuisance of
it.  The blotch variants treat the blotches as what the renderer makes them, a smooth
random field whose statistics are known and whose values are not.  Worth reading only
if (1) those statistics are the renderer's, (2) its columns are the renderer's
derivatives, and (3) its information behaves as information must: a random nuisance
never adds any, more pixels never remove any, and the modes it keeps are enough.
"""

import numpy as np
import pytest

import station.bench.vision_bound as vb
from station.bench.vision_bound import (FRAME_GEOMETRY, HoleCase, _blotch_correlation, _blotch_modes_1d, _Geometry,
                                        blotch_pitch_px, combine_frame, fisher)


def _case(r, blur=1.5, blotch=0.05, **kw):
    base = dict(radius_px=r, blur_px=blur, wall_dn=150, hole_dn=70, grain=0.03, gain_e_per_dn=40,
                read_noise_dn=1.5, vignetting_gain=0.9, frac_x=0.2, frac_y=-0.3, illum_gx=4e-4, illum_gy=-2e-4,
                blotch=blotch, blotch_pitch_px=blotch_pitch_px(1280, 1024))
    return HoleCase(**{**base, **kw})


def _sigma(case, **kw):
    return combine_frame([fisher(case, **{**FRAME_GEOMETRY, **kw})])[0]


def test_the_bounds_blotch_statistics_are_the_renderers():
    """The correlation the bound gives the blotches against the renderer's own fields
    (``sim.camera.render._lowfreq`` on a 1280 x 1024 frame, 40 of them), along x and y at
    lags 0-120 px: within 0.035. The pitch matters: the renderer's nominal 64 px cell
    instead of the 58.2 px its resize makes is 0.08 off at 45 px."""
    from sim.camera.render import _lowfreq

    rng = np.random.default_rng(5)
    lags = np.array([0, 10, 20, 30, 45, 60, 90, 120])
    emp_x, emp_y = np.zeros(lags.size), np.zeros(lags.size)
    for _ in range(40):
        f = _lowfreq(rng, 1280, 1024, 64).astype(float)
        for i, lag in enumerate(lags):
            emp_x[i] += np.mean(f[:, : 1280 - lag] * f[:, lag:]) / 40
            emp_y[i] += np.mean(f[: 1024 - lag, :] * f[lag:, :]) / 40
    px, py = blotch_pitch_px(1280, 1024)
    assert (px, py) == pytest.approx((1280 / 22, 1024 / 18))
    assert np.max(np.abs(_blotch_correlation(lags.astype(float), px) - emp_x)) < 0.035
    assert np.max(np.abs(_blotch_correlation(lags.astype(float), py) - emp_y)) < 0.035
    assert abs(_blotch_correlation(np.array([45.0]), 64.0)[0] - emp_x[4]) > 0.06


@pytest.mark.parametrize("blur, diameter", [(1.0, 40.0), (2.0, 24.0)])
def test_the_bounds_blotch_columns_are_the_renderers(blur, diameter):
    """Each blotch mode's column against the renderer's derivative: the wall times
    (1 + the mode), cut by the hole's pixel coverage and blurred by cv2 (central
    differences), on the bound's pixels: within 1 %."""
    import cv2

    from sim.camera.render import FrameParams, HoleSpec, hole_coverage

    size, c0 = 200, 100
    params = FrameParams(width_px=size, height_px=size, wall_level_dn=150.0, hole_level_dn=70.0, groove_depth=0.0,
                         grain=0.0, blotch=0.0, blur_sigma_px=blur, vignetting=0.0)
    hole = HoleSpec(c0 + 0.2, c0 - 0.3, diameter)
    (x0, y0, x1, y1), cover, _, _ = hole_coverage(hole, params)

    def image(wall):
        rad = np.asarray(wall, np.float32) * np.ones((size, size), np.float32)
        rad[y0:y1, x0:x1] = rad[y0:y1, x0:x1] * (1 - cover) + 70.0 * cover
        return cv2.GaussianBlur(rad, (0, 0), blur, borderType=cv2.BORDER_REFLECT).astype(float)

    case = _case(diameter / 2, blur=blur, vignetting_gain=1.0, illum_gx=0.0, illum_gy=0.0)
    geo = _Geometry(case, blur_known=False, with_grain=True, blotch_prior=True, **FRAME_GEOMETRY)
    n = geo.shape[0]
    ext = (n - 1) // 2
    half = (geo.jac.shape[1] - 1) // 2
    assert ext < c0
    idx = np.arange(n) - ext
    lam_y, vy = _blotch_modes_1d(idx, case.blotch_pitch_px[1])
    lam_x, vx = _blotch_modes_1d(idx, case.blotch_pitch_px[0])
    win = (slice(c0 - half, c0 + half + 1),) * 2
    assert len(geo.prior_names) > 10
    for name in geo.prior_names[:3] + geo.prior_names[-2:]:
        i, j = (int(t) for t in name.split("_")[1:])
        mode = np.zeros((size, size))
        mode[c0 - ext: c0 + ext + 1, c0 - ext: c0 + ext + 1] = np.outer(vy[:, i], vx[:, j])
        amp = np.sqrt(lam_y[i] * lam_x[j]) * case.blotch
        ref = (image(150.0 * (1 + amp * mode)) - image(150.0 * (1 - amp * mode)))[win] / 2.0 * geo.mask
        col = geo.jac[geo.names.index(name)]
        assert np.linalg.norm(col - ref) / np.linalg.norm(ref) < 0.01, name


def test_a_random_blotch_field_costs_information_and_a_wider_read_takes_some_back():
    """On a 40 px hole with 5 % blotches: the field's prior can only raise the bound (here
    by more than 1 %), a disc read 40 px past the rim lowers it again (more pixels, never
    less information), and the modes left out below ``BLOTCH_MODE_TOL`` change it by less
    than 0.2 %."""
    case = _case(40.0)
    plain = _sigma(case)
    prior = _sigma(case, blotch_prior=True)
    assert prior[0] > 1.01 * plain[0]
    assert np.all(np.diag(prior[1]) > np.diag(plain[1]))
    wide = _sigma(case, blotch_prior=True, fit_reach_px=40.0)
    assert wide[0] < prior[0]
    tol = vb.BLOTCH_MODE_TOL
    try:
        vb.BLOTCH_MODE_TOL = tol / 10
        finer = _sigma(case, blotch_prior=True)
    finally:
        vb.BLOTCH_MODE_TOL = tol
    assert finer[0] == pytest.approx(prior[0], rel=2e-3)
    assert finer[0] >= prior[0] * (1 - 1e-6)  # more modes: more nuisance, never less


def test_a_frame_gives_the_blotch_variant_alone_and_it_needs_the_grooves():
    """``frame_bounds`` computes the variants asked for and no other; the blotch variants,
    like the grooved bound they extend, need the frame's grooves, and say so."""
    from dataclasses import replace

    from sim.camera.render import random_frame

    cases = vb.cases_from_frame(random_frame(1003, keep_grooves=True))
    assert len(cases) == 1 and cases[0].blotch > 0
    only = vb.frame_bounds(cases, variants=("frame_aware_blotches",))
    assert set(only) == {"frame_aware_blotches"}
    grooved = vb.frame_bounds(cases, variants=(vb.GROOVED,))[vb.GROOVED]
    assert only["frame_aware_blotches"][0][0] > grooved[0][0]
    with pytest.raises(ValueError, match="frame_aware_blotches_wide bound needs the frame's grooves"):
        vb.frame_bounds([replace(cases[0], grooves=None)], variants=("frame_aware_blotches_wide",))
