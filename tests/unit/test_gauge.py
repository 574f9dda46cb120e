"""Type-1 gauge study formulas, checked by hand."""

import math

import pytest

from station.inspection.gauge import plot_gauge, type1


def test_cg_cgk_by_hand(tmp_path):
    # values with mean 10.001 and s = 0.001 exactly: 10.000, 10.001, 10.002
    r = type1("x", [10.000, 10.001, 10.002], reference=10.0, lower=9.9, upper=10.1)
    assert r.s == pytest.approx(0.001)
    assert r.bias == pytest.approx(0.001)
    # Cg = 0.2 * 0.2 / (6 * 0.001) = 6.667; Cgk = (0.1 * 0.2 - 0.001) / (3 * 0.001) = 6.333
    assert r.cg == pytest.approx(0.04 / 0.006)
    assert r.cgk == pytest.approx(0.019 / 0.003)
    plot_gauge([r, type1("y", [1.0, 1.5, 2.0], 1.5, 0.0, 3.0)], tmp_path / "g.png")
    assert (tmp_path / "g.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_gauge_needs_two_values_and_handles_zero_spread():
    with pytest.raises(ValueError, match="at least 2"):
        type1("x", [1.0], 1.0, 0.0, 2.0)
    r = type1("x", [1.0, 1.0], 1.0, 0.0, 2.0)
    assert math.isinf(r.cg) and r.to_json()["cg"] is None
