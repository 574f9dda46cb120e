"""Rotary baselines never step silently at 0/360 deg (issue 18, defect 3)."""

from __future__ import annotations

import numpy as np
import pytest

from station.effects import ErrorCurve


def test_whole_turn_that_does_not_close_is_refused_naming_both_ends():
    with pytest.raises(ValueError, match=r"0 arcsec at 0 deg, 49.5 arcsec at 360 deg"):
        ErrorCurve.table([0.0, 180.0, 360.0], [0.0, 20.0, 49.5], "rotary")


def test_closed_whole_turn_is_periodic_without_a_step():
    cv = ErrorCurve.table([0.0, 90.0, 180.0, 270.0, 360.0], [5.0, 10.0, 15.0, 10.0, 5.0], "rotary")
    assert cv.baseline(np.array([0.0, 360.0, 720.0, -0.0]))[:3] == pytest.approx([5.0, 5.0, 5.0])
    eps = 1e-6
    assert cv.baseline(np.array([360.0 - eps]))[0] == pytest.approx(cv.baseline(np.array([eps]))[0], abs=1e-3)
    assert cv.baseline(np.array([45.0]))[0] == pytest.approx(7.5)


def test_part_turn_closes_linearly_across_its_gap():
    cv = ErrorCurve.table([0.0, 100.0, 300.0], [0.0, 10.0, 30.0], "rotary")
    # from 30 at 300 back to 0 at 360: continuous through the wrap
    assert cv.baseline(np.array([330.0, 359.999, 0.0]))== pytest.approx([15.0, 0.0005, 0.0], abs=1e-3)


def test_linear_tables_unchanged():
    cv = ErrorCurve.table([0.0, 100.0], [0.0, 49.5], "linear")
    assert cv.baseline(np.array([-5.0, 0.0, 100.0, 200.0])) == pytest.approx([0.0, 0.0, 49.5, 49.5])


def test_discovery_model_file_with_an_open_turn_is_refused_by_name(tmp_path):
    from station.axis_model import AxisModelError, read_axis_model

    p = tmp_path / "c.toml"
    p.write_text('[axis]\nname = "C"\nkind = "rotary"\n[baseline]\ntarget = [0.0, 180.0, 360.0]\n'
                 'deviation = [0.0, 20.0, 49.5]\n[noise]\nsigma = 0.5\n')
    with pytest.raises(AxisModelError, match=r"c\.toml.*0 arcsec at 0 deg, 49\.5 arcsec at 360 deg"):
        read_axis_model(p)
