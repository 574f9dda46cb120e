"""Camera calibration round trip and measurement through a distorting lens.

Tolerances: with 10 chessboard views and corners found to ~0.05 px (RMS reprojection
error), OpenCV recovers the focal length to ~0.1 % and the principal point to ~1 px;
we allow 0.5 % and 3 px.  What measurement needs is the undistortion map, which the
views constrain where the board was: over the central 80 % of the frame it must agree
with the true lens to 0.25 px (holes near the border carry more uncertainty, stated
in docs/vision.md).
"""

from __future__ import annotations

import numpy as np
import pytest

from sim.camera.lens import BrownLens
from sim.camera.render import random_frame
from sim.camera.target import board_views
from station.vision import CameraCalibration, calibrate, measure_holes
from station.vision.scoring import Score, score_frame

LENS = BrownLens(k1=-0.22, k2=0.06, p1=8e-4, p2=-5e-4)  # endoscope barrel distortion


@pytest.fixture(scope="module")
def calibration() -> CameraCalibration:
    views = board_views(LENS, n_views=10, seed=1)
    return calibrate([v.image for v in views], (9, 7), 0.5, working_distance_mm=11.0)


def test_round_trip_recovers_intrinsics_and_distortion(calibration):
    k = calibration.camera_matrix
    assert calibration.n_views == 10 and calibration.rms_px < 0.15
    assert k[0, 0] == pytest.approx(LENS.fx_px, rel=5e-3) and k[1, 1] == pytest.approx(LENS.fy_px, rel=5e-3)
    assert k[0, 2] == pytest.approx(LENS.cx_px, abs=3.0) and k[1, 2] == pytest.approx(LENS.cy_px, abs=3.0)
    assert calibration.dist_coeffs[0] == pytest.approx(LENS.k1, abs=0.02)
    yy, xx = np.mgrid[102:922:16, 128:1152:16].astype(float)  # central 80 %
    pts = np.stack([xx.ravel(), yy.ravel()], 1)
    true = np.stack(LENS.undistort_px(pts[:, 0], pts[:, 1]), 1)
    assert np.abs(calibration.undistort_px(pts) - true).max() < 0.25
    # the scale at the wall: working distance / focal length
    assert calibration.mm_per_px == pytest.approx(11.0 / 1400.0, rel=5e-3)


def test_json_round_trip(tmp_path, calibration):
    path = tmp_path / "cal.json"
    calibration.save(path)
    back = CameraCalibration.load(path)
    np.testing.assert_allclose(back.camera_matrix, calibration.camera_matrix)
    np.testing.assert_allclose(back.dist_coeffs, calibration.dist_coeffs)
    assert back.image_size == calibration.image_size and back.mm_per_px == calibration.mm_per_px


def test_holes_through_a_distorting_lens_measured_in_ideal_pixels(calibration):
    """Undistorted edge points give the hole in ideal pixels; uncalibrated, the lens errs."""
    cal_total, raw_total = Score(), Score()
    for i in range(4):
        f = random_frame(300 + i, n_whole=3, n_partial=0, lens=LENS)
        truths = [(h.x_px, h.y_px, h.diameter_px, h.partial) for h in f.holes]
        ms = measure_holes(f.image, calibration=calibration)
        cal_total.add(score_frame(truths, [(m.x_px, m.y_px, m.diameter_px, m.partial) for m in ms]))
        raw = measure_holes(f.image)
        raw_total.add(score_frame(truths, [(m.x_px, m.y_px, m.diameter_px, m.partial) for m in raw]))
        assert all(m.diameter_mm == pytest.approx(m.diameter_px * calibration.mm_per_px) for m in ms)
    s, r = cal_total.summary(), raw_total.summary()
    assert s["misses"] == 0 and s["phantoms"] == 0
    # the calibration's own error adds to the measurement's: bars a little wider
    assert s["median_centre_err_px"] <= 0.1 and s["median_diameter_err_px"] <= 0.1
    assert s["worst_diameter_err_px"] <= 0.3
    assert r["median_centre_err_px"] > 3 * s["median_centre_err_px"]  # distortion matters
