"""The master checks read together: a step, a drift, steady, or not yet known."""

from __future__ import annotations

import numpy as np
import pytest

from station.monitor.evidence import MasterRecord, explain, scale_of

HOLES = {"hole_1": 71.03, "hole_2": 85.19}
U = 0.45  # combined standard uncertainty of one hole's error (um)


def records(errors, times_s, seed=0, scale_ppm=0.0):
    rng = np.random.default_rng(seed)
    out = []
    for k, (e, t) in enumerate(zip(errors, times_s)):
        err = {h: e + scale_ppm * 1e-3 * (a - 78.11) + rng.normal(0.0, U) for h, a in HOLES.items()}
        out.append(MasterRecord(t, 5 * (k + 1), dict(HOLES), err, {h: U for h in HOLES}))
    return out


@pytest.mark.parametrize("seed", range(5))
def test_a_knock_is_a_step_between_the_two_checks_it_fell_between(seed):
    t = [70.0 * k for k in range(1, 6)]
    ex = explain(records([0.0, 0.0, 0.0, 8.0, 8.0], t, seed))
    assert ex.kind == "step", ex
    assert ex.step_between_s == (t[2], t[3])
    assert all(abs(v - 8.0) < 1.2 for v in ex.now_um.values()), ex.now_um


@pytest.mark.parametrize("seed", range(5))
def test_a_warming_is_a_drift_with_its_rate(seed):
    t = np.arange(1, 7) * 70.0
    rate_um_per_h = 50.0
    ex = explain(records(list(rate_um_per_h * t / 3600.0), list(t), seed))
    assert ex.kind == "drift", ex
    assert abs(ex.rate_um_per_h - rate_um_per_h) < 3.0 * ex.rate_u_um_per_h
    # the value now comes from the line through all the checks
    assert abs(np.mean(list(ex.now_um.values())) - rate_um_per_h * t[-1] / 3600.0) < 1.0


def test_a_knock_caught_at_the_last_check_is_a_step():
    ex = explain(records([0.0, 0.0, 0.0, 0.0, 8.0], [70.0 * k for k in range(1, 6)], seed=1))
    assert ex.kind == "step" and ex.step_between_s == (280.0, 350.0)


def test_two_checks_cannot_tell_a_step_from_a_drift():
    ex = explain(records([0.0, 4.0], [70.0, 140.0]))
    assert ex.kind == "unknown" and ex.checks == 2
    assert "next check" in ex.description


@pytest.mark.parametrize("seed", range(5))
def test_checks_that_agree_are_steady(seed):
    ex = explain(records([1.5] * 6, list(np.arange(1, 7) * 70.0), seed))
    assert ex.kind == "steady", ex
    assert not ex.drifting


def test_the_scale_the_holes_show_is_measured_with_its_uncertainty():
    t = list(np.arange(1, 9) * 70.0)
    recs = records([2.0] * 8, t, seed=3, scale_ppm=150.0)
    s, u = scale_of(recs)
    assert abs(s - 150.0) < 3.0 * u
    # one hole's place cannot show a scale
    one = [MasterRecord(r.time_s, r.index, {"hole_1": 71.0}, {"hole_1": r.error_um["hole_1"]}, {"hole_1": U})
           for r in recs]
    assert scale_of(one) is None


def test_no_checks_is_refused():
    with pytest.raises(ValueError, match="no master checks"):
        explain([])
