"""The scan's GUM budget (``station.inspection.scan.combine``) against figures worked by hand."""

import math

import pytest

from station.inspection.scan import CameraGeometry, FrameObservation, HoleResult, ScanSettings, combine

GEO = CameraGeometry(mm_per_px=0.01, width_px=1281, height_px=1025, bore_radius_mm=11.1, scale_u_rel=2e-4)
CY = 512.0  # (1025 - 1) / 2


def _frame(axial, y_px, diameter_px, u_px, y_u_px):
    return FrameObservation(axial_mm=axial, angle_deg=0.0, diameter_mm=diameter_px * GEO.mm_per_px, x_px=640.0,
                            y_px=y_px, diameter_px=diameter_px, confidence=0.9, grating_mm=None, z_cmd_mm=0.0,
                            c_cmd_deg=0.0, diameter_u_px=u_px, y_u_px=y_u_px)


def _hole(us, y_us=(None,) * 5):
    r = HoleResult("hole_1", True)
    # five frames: diameters 70.00, 70.02, 69.98, 70.01, 69.99 px; the hole 12 px above
    # the frame's centre (offset 0.12 mm); axial positions scattered by a few um
    for dx, u, yu, da in zip((0.0, 0.02, -0.02, 0.01, -0.01), us, y_us, (0.0, 1e-3, -1e-3, 2e-3, -2e-3)):
        r.frames.append(_frame(85.0 + da, CY - 12.0, 70.0 + dx, u, yu))
    return r


def _sd_of_mean(values):
    n = len(values)
    m = sum(values) / n
    return math.sqrt(sum((v - m) ** 2 for v in values) / (n - 1) / n)


def test_the_diameter_takes_the_holes_own_vision_uncertainty():
    settings = ScanSettings()
    r = _hole([0.02, 0.03, 0.025, 0.02, 0.03])
    combine(r, GEO, settings)
    dia = [f.diameter_mm for f in r.frames]
    d = sum(dia) / 5
    # Type A: the frames' scatter; scale: 2e-4 of the diameter; vision: the mean of the
    # frames' own u (0.025 px), not divided by the number of frames
    u = math.sqrt(_sd_of_mean(dia) ** 2 + (2e-4 * d) ** 2 + (0.025 * 0.01) ** 2)
    assert r.diameter_mm == pytest.approx(d, abs=1e-12)
    assert r.diameter_u_mm == pytest.approx(2 * u, rel=1e-9)
    # the fixed 0.07 px term would have given a larger U
    assert r.diameter_u_mm < 2 * math.sqrt(_sd_of_mean(dia) ** 2 + (2e-4 * d) ** 2 + (0.07 * 0.01) ** 2)


def test_a_frame_without_its_own_uncertainty_falls_back_to_the_fixed_term():
    settings = ScanSettings(vision_diameter_u_px=0.07)
    for us in ([0.02, None, 0.02, 0.02, 0.02], [0.02, float("nan"), 0.02, 0.02, 0.02], [None] * 5):
        r = _hole(us)
        combine(r, GEO, settings)
        dia = [f.diameter_mm for f in r.frames]
        d = sum(dia) / 5
        u = math.sqrt(_sd_of_mean(dia) ** 2 + (2e-4 * d) ** 2 + (0.07 * 0.01) ** 2)
        assert r.diameter_u_mm == pytest.approx(2 * u, rel=1e-9), us


def _position_u(ax, vision_px):
    # Type A, the scale times the hole's offset from the frame's centre (0.12 mm), the
    # model's residual (0.1 um), the vision term
    return math.sqrt(_sd_of_mean(ax) ** 2 + (2e-4 * 0.12) ** 2 + (0.1e-3) ** 2 + (vision_px * 0.01) ** 2)


def test_the_position_takes_the_holes_own_centre_uncertainty_along_the_axis():
    settings = ScanSettings(model_u_um=0.1, vision_centre_u_px=0.05)
    r = _hole([0.02] * 5, [0.010, 0.012, 0.014, 0.010, 0.014])
    combine(r, GEO, settings)
    ax = [f.axial_mm for f in r.frames]
    assert r.position_mm == pytest.approx(sum(ax) / 5, abs=1e-12)
    assert r.position_u_mm == pytest.approx(2 * _position_u(ax, 0.012), rel=1e-9)


def test_the_position_falls_back_to_the_fixed_centre_term():
    settings = ScanSettings(model_u_um=0.1, vision_centre_u_px=0.05)
    for y_us in ((None,) * 5, (0.01, 0.01, None, 0.01, 0.01)):
        r = _hole([0.02] * 5, y_us)
        combine(r, GEO, settings)
        assert r.position_u_mm == pytest.approx(2 * _position_u([f.axial_mm for f in r.frames], 0.05), rel=1e-9)
