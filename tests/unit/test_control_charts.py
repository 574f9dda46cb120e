"""Control charts: the EWMA's run lengths against published tables and a Monte Carlo,
and the station's watch on synthetic evidence (in control, a step, a knocked datum)."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from station.monitor.ewma import EwmaChart, arl, limit_for_arl
from station.monitor.watch import CharacteristicCheck, StationWatch, grating_residual_um


@pytest.mark.parametrize("lam, L", [(0.05, 2.615), (0.10, 2.814), (0.20, 2.962)])
def test_in_control_arl_matches_lucas_and_saccucci(lam, L):
    # Lucas and Saccucci (1990), Table 3: these (lam, L) give an in-control ARL of 500
    assert arl(lam, L) == pytest.approx(500.0, rel=0.01)


def test_arl_agrees_with_a_monte_carlo_of_the_chart():
    lam, L = 0.2, 2.2
    rng = np.random.default_rng(7)
    runs, n = [], 4000
    h = L * np.sqrt(lam / (2 - lam))
    z = np.zeros(n)
    alive = np.ones(n, bool)
    length = np.zeros(n, int)
    t = 0
    while alive.any() and t < 5000:
        t += 1
        z = np.where(alive, lam * rng.standard_normal(n) + (1 - lam) * z, z)
        out = alive & (np.abs(z) > h)
        length[out] = t
        alive &= ~out
    runs = length[length > 0]
    assert len(runs) == n
    # the mean of 4000 geometric-like run lengths: within 5 % (its standard error is 1.6 %)
    assert runs.mean() == pytest.approx(arl(lam, L), rel=0.05)
    # a shifted process is caught sooner
    assert arl(lam, L, shift=2.0) < arl(lam, L) / 10


def test_limit_for_arl_inverts_arl():
    L = limit_for_arl(0.2, 50000.0)
    assert arl(0.2, L) == pytest.approx(50000.0, rel=0.002)
    with pytest.raises(ValueError):
        arl(0.0, 3.0)


def test_chart_signals_beyond_its_asymptotic_limit_and_refuses_nan():
    c = EwmaChart("x", lam=0.5, L=2.0)
    assert c.limit == pytest.approx(2.0 * np.sqrt(0.5 / 1.5))
    assert not c.add(1.0) and c.z == pytest.approx(0.5)
    assert c.add(3.0)  # 0.5 * 3 + 0.5 * 0.5 = 1.75 > 1.155
    with pytest.raises(ValueError):
        c.add(float("nan"))


def holes(residuals_um, frames=5):
    """HoleResult-like objects whose frames read the grating ``r`` um from the model."""
    return [SimpleNamespace(frames=[SimpleNamespace(grating_mm=70.0 + r * 1e-3, carriage_pred_mm=70.0)] * frames)
            for r in residuals_um]


def test_grating_residual_is_the_mean_over_holes_of_their_frames():
    r, n = grating_residual_um(holes([0.5, 1.5]))
    assert (r, n) == (pytest.approx(1.0), 2)
    assert grating_residual_um([SimpleNamespace(frames=[SimpleNamespace(grating_mm=None, carriage_pred_mm=1.0)])]) is None


def test_watch_in_control_then_a_step_beyond_u_is_caught_within_ten_inspections():
    rng = np.random.default_rng(11)
    w = StationWatch(z_repeatability_um=0.3)
    offset = 0.8  # the world's model differs by a constant: Phase I takes it as the baseline
    for _ in range(3000):
        assert w.observe_inspection(holes(offset + 0.3 * rng.standard_normal(2))) == []
    assert not w.state()["needs_check"] and w.baseline_um == pytest.approx(offset, abs=0.3)
    # the grating starts to read 1 um short (a warm scale): more than the stated model u
    for k in range(1, 11):
        alarms = w.observe_inspection(holes(offset - 1.0 + 0.3 * rng.standard_normal(2)))
        if alarms:
            break
    assert alarms and alarms[0].chart == "grating" and k <= 10
    assert w.state()["needs_check"] and "check it on the master" in w.state()["reason"]


def test_a_small_departure_within_the_model_u_does_not_alarm():
    rng = np.random.default_rng(3)
    w = StationWatch(z_repeatability_um=0.3, gate_um=0.35)
    for i in range(400):
        drift = 0.1 if i > 50 else 0.0  # real, detectable, but well below what the station states
        assert w.observe_inspection(holes(drift + 0.3 * rng.standard_normal(2))) == []


def check(dz_um=0.0, rng=None):
    noise = (lambda: 0.0) if rng is None else (lambda: 0.45e-3 * rng.standard_normal())
    return [CharacteristicCheck(f"hole_{i}.position", 71.0 + dz_um * 1e-3 + noise(), 71.0, 0.37e-3, 0.3e-3)
            for i in (1, 2)]


def test_master_checks_in_control_clear_and_a_knocked_datum_alarms_at_once():
    rng = np.random.default_rng(5)
    w = StationWatch()
    for _ in range(300):
        assert w.observe_master(check(rng=rng)) == []
    alarms = w.observe_master(check(8.0, rng))
    assert alarms and alarms[0].chart == "master" and "outside its stated U" in alarms[0].reason
    assert w.state()["needs_check"]
    assert w.observe_master(check(rng=rng)) == []  # the datum set right again: a check in control clears
    assert not w.state()["needs_check"]
    assert CharacteristicCheck("x", 1.001, 1.0, 0.0003, 0.0004).en == pytest.approx(1.0)


def test_master_bias_within_the_stated_u_is_not_an_alarm_and_beyond_it_is():
    rng = np.random.default_rng(9)

    def biased(z_bias):
        u = np.hypot(0.37e-3, 0.3e-3)
        return [CharacteristicCheck(f"hole_{i}.position", 71.0 + z_bias * u + u * rng.standard_normal(), 71.0,
                                    0.37e-3, 0.3e-3) for i in (1, 2)]

    w = StationWatch()
    # the world's datum 0.8 combined standard uncertainties off: real, and inside U (k = 2)
    for _ in range(500):
        assert w.observe_master(biased(0.8)) == []
    # 3 combined standard uncertainties off (E_n 1.5), below the single-characteristic rule: the
    # chart or the pooled rule finds it
    for k in range(1, 11):
        if w.observe_master(biased(3.0)):
            break
    else:
        pytest.fail("a bias beyond the stated U went unnoticed for 10 checks")
    reason = w.state()["reason"]
    assert w.state()["needs_check"] and ("drift from the certificate" in reason or "on average (pooled" in reason)


def scattered_holes(rng, sigma_um, n_holes=2, frames=5):
    """Holes whose frames read the axial place with ``sigma_um`` of scatter (no grating)."""
    return [SimpleNamespace(frames=[SimpleNamespace(axial_mm=71.0 + rng.normal(0.0, sigma_um) * 1e-3, grating_mm=None,
                                                    carriage_pred_mm=None) for _ in range(frames)])
            for _ in range(n_holes)]


def test_frame_scatter_chart_is_quiet_in_control_and_catches_a_doubled_scatter():
    from station.monitor.watch import frame_scatter_um2

    rng = np.random.default_rng(7)
    s2, nu = frame_scatter_um2(scattered_holes(rng, 0.3, frames=200))
    assert nu == 2 * 199 and abs(s2 - 0.09) < 0.02
    w = StationWatch()
    # Phase I, then 300 in-control inspections: nothing (ARL0 1e5 per inspection)
    assert not any(w.observe_inspection(scattered_holes(rng, 0.3)) for _ in range(320))
    assert w.scatter_ref_um2 is not None and abs(w.scatter_ref_um2 - 0.09) < 0.03
    # the endoscope comes loose: twice the scatter is seen within a few inspections
    for k in range(1, 16):
        alarms = w.observe_inspection(scattered_holes(rng, 0.6))
        if alarms:
            break
    assert alarms and alarms[0].chart == "scatter" and "scatter grew" in alarms[0].reason, k
    assert k <= 8 and w.needs_check


def test_a_smaller_scatter_is_not_an_alarm():
    rng = np.random.default_rng(8)
    w = StationWatch()
    for _ in range(20):
        w.observe_inspection(scattered_holes(rng, 0.3))
    assert not any(w.observe_inspection(scattered_holes(rng, 0.1)) for _ in range(50))
