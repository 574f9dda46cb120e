"""The frame's illumination field and the flat-fielding of each hole before the photometric fit.

Vignetting multiplies the hole's dark level as well as the wall; a fit whose hole level is
a constant read the gradient across the hole as a displaced rim (a centre bias of 0.1 px
on a clean 80 px hole near a corner).
"""

import numpy as np
import pytest

from sim.camera.render import FrameParams, HoleSpec, random_frame, render_frame
from station.vision.illumination import estimate_illumination
from station.vision.measure import MeasureConfig, measure_holes


def _true_relative_gradient(p: FrameParams, x: float, y: float) -> np.ndarray:
    """The renderer's vignetting, 1 - v r^2 / r_c^2 about the frame centre: grad / value."""
    cx, cy = (p.width_px - 1) / 2, (p.height_px - 1) / 2
    rc2 = (p.width_px / 2) ** 2 + (p.height_px / 2) ** 2
    g = 1 - p.vignetting * ((x - cx) ** 2 + (y - cy) ** 2) / rc2
    return np.array([-2 * p.vignetting * (x - cx), -2 * p.vignetting * (y - cy)]) / rc2 / g


def test_the_illumination_gradient_is_read_from_a_textured_frame():
    """Honed texture, blotches, noise and the holes themselves: the field's relative
    gradient at every hole within 15 % (RMS) of the renderer's vignetting."""
    err, true = [], []
    for seed in range(4000, 4020):
        f = random_frame(seed)
        ill = estimate_illumination(f.image)
        for h in f.holes:
            t = _true_relative_gradient(f.params, h.x_px, h.y_px)
            err.append(np.array(ill.relative_gradient(h.x_px, h.y_px)) - t)
            true.append(t)
    assert len(true) > 20
    rms_err, rms_true = np.sqrt(np.mean(np.square(err))), np.sqrt(np.mean(np.square(true)))
    assert rms_err < 0.15 * rms_true, (rms_err, rms_true)


def test_flat_fielding_removes_the_vignetting_bias_from_the_centre():
    p = FrameParams(groove_depth=0.0, grain=0.0, blotch=0.0, blur_sigma_px=2.0, gain_e_per_dn=1e9,
                    read_noise_dn=0.0, vignetting=0.4, wall_level_dn=160, hole_level_dn=70)
    hole = HoleSpec(180.3, 160.7, 80.0)
    f = render_frame(p, [hole], seed=1)
    (raw,) = measure_holes(f.image, cfg=MeasureConfig(flat_field=False))
    (flat,) = measure_holes(f.image, cfg=MeasureConfig())
    assert np.hypot(raw.x_px - hole.x_px, raw.y_px - hole.y_px) > 0.05  # the bias is there
    assert np.hypot(flat.x_px - hole.x_px, flat.y_px - hole.y_px) < 0.005
    # the mean radius: the annulus alone does not see a linear tilt (to first order), but
    # the hole's inside, which pins the hole's level, does: flat-fielded, the diameter is
    # right, and no worse than without
    assert flat.diameter_px == pytest.approx(hole.diameter_px, abs=0.005)
    assert abs(flat.diameter_px - hole.diameter_px) <= abs(raw.diameter_px - hole.diameter_px) + 0.001


def test_a_flat_frame_has_no_gradient_and_a_tiny_one_no_field():
    """No vignetting: what is read is the texture's noise (2.8e-5 / px RMS on the envelope's
    frames, whose vignetting gradients are 3.6e-4 / px RMS at the holes): below 1e-4."""
    p = FrameParams(vignetting=0.0)
    ill = estimate_illumination(render_frame(p, [HoleSpec(300.0, 250.0, 60.0)], seed=3).image)
    for x, y in ((100.0, 100.0), (640.0, 512.0), (1200.0, 950.0)):
        gx, gy = ill.relative_gradient(x, y)
        assert abs(gx) < 1e-4 and abs(gy) < 1e-4, (x, y, gx, gy)
    assert estimate_illumination(np.full((60, 80), 120, np.uint8)) is None


def test_the_fields_relative_curvature_completes_its_expansion_about_a_pixel():
    """P is a quadratic, so P(x + dx, y + dy) / P(x, y) = 1 + g . d + qxx dx^2 + qxy dx dy
    + qyy dy^2 with no remainder: the hole's level takes its curvature from it."""
    from station.vision.illumination import Illumination

    ill = Illumination((120.0, 3.0, -2.0, -30.0, 4.0, -25.0), (639.5, 511.5), (640.0, 512.0))
    x, y = 300.0, 700.0
    gx, gy = ill.relative_gradient(x, y)
    qxx, qxy, qyy = ill.relative_curvature(x, y)
    for dx, dy in ((50.0, 0.0), (0.0, -40.0), (35.0, 28.0), (-60.0, 45.0)):
        expect = ill.value(x + dx, y + dy) / ill.value(x, y)
        got = 1 + gx * dx + gy * dy + qxx * dx * dx + qxy * dx * dy + qyy * dy * dy
        assert got == pytest.approx(expect, abs=1e-12)
    assert qxx < 0 and qyy < 0  # a field that falls off from the centre
