"""The parts of discovery on their own: noise floor, whitening, scans, outliers, gates, bench."""

from __future__ import annotations

import numpy as np

from station.discovery import discover
from station.discovery.data import prepare
from station.discovery.noise import Whitener, estimate_noise
from station.discovery.scans import periodic_scan
from station.discovery.synth import Campaign, ar1_noise, linear_model, make_recording
from station.discovery.whiteness import runs_test, whiteness
from station.effects import VOCABULARY, Backlash, Periodic


def test_noise_floor_recovers_sigma_and_phi_despite_effects():
    model = linear_model()
    sig, phi = [], []
    for seed in range(8):
        rec = make_recording(model, (Backlash(4.0), Periodic(30.0, 2.0, 0.3)), Campaign(seed=seed, sigma=0.5, phi=0.4))
        nf = estimate_noise(prepare(model, rec))
        sig.append(nf.sigma)
        phi.append(nf.phi)
    assert abs(np.mean(sig) - 0.5) < 0.06      # effects of position and direction cancel in repeats
    assert abs(np.mean(phi) - 0.4) < 0.1
    assert nf.n_eff < len(rec)


def test_whitening_makes_ar1_noise_white():
    rng = np.random.default_rng(1)
    run = np.repeat(np.arange(1, 11), 100)
    e = ar1_noise(run, 1.0, 0.6, rng)
    prev = np.where(np.r_[False, run[1:] == run[:-1]], np.arange(run.size) - 1, -1)
    assert not whiteness(e)["white"]
    w = Whitener(prev, 0.6)
    assert whiteness(w(e))["white"]
    assert np.allclose(w.along_last(np.stack([e, 2 * e])), np.stack([w(e), 2 * w(e)]))
    # the gather path (runs interleaved in file order) agrees with the slice path
    w2 = Whitener(prev, 0.6)
    w2.contiguous = False
    assert np.allclose(w2.along_last(e[None, :])[0], w(e))


def test_runs_test_detects_long_stretches():
    assert runs_test(np.r_[np.ones(50), -np.ones(50)]) < 1e-6
    assert runs_test(np.random.default_rng(0).normal(size=200)) > 0.01


def test_periodic_scan_finds_period_and_reports_false_alarm_probability():
    rng = np.random.default_rng(2)
    x = np.sort(rng.uniform(0, 120, 400))
    prev = np.r_[-1, np.arange(399)]
    w = Whitener(prev, 0.0)
    y = 0.8 * np.sin(2 * np.pi * x / 7.3 + 0.5) + rng.normal(0, 0.5, x.size)
    scan = periodic_scan(x, y, w, 1.0, 80.0, nuisance=np.column_stack([np.ones_like(x), x]))
    assert abs(scan.best_period - 7.3) < 0.05 * 7.3 and scan.fap < 1e-6
    assert abs(scan.best_amplitude - 0.8) < 0.2
    noise_only = periodic_scan(x, rng.normal(0, 0.5, x.size), w, 1.0, 80.0)
    assert noise_only.fap > 0.01


def test_clean_data_trials_are_refused_with_reasons():
    model = linear_model()
    report = discover(model, make_recording(model, (), Campaign(seed=11))).report
    assert report["verdict"] == "no-mismatch"
    trials = report["selection"]["trials"][0]
    assert {t["name"] for t in trials} >= {"offset", "scale", "backlash", "thermal_drift", "periodic"}
    assert all(t["refused_because"] for t in trials)


def test_local_defect_is_registered_in_the_vocabulary():
    import station.discovery  # noqa: F401  (registers)

    assert "local_defect" in VOCABULARY


def test_bench_runs_and_reports_every_measure():
    from station.bench.discovery import EFFECTS, run_bench

    res = run_bench(n_clean=4, per_effect=1, timing_repeats=1)
    assert 0.0 <= res["false_claim_rate"] <= 1.0
    assert set(res["power"]) == set(EFFECTS)
    assert res["time_10k_rows"] >= 10_000
    assert res["time_10k_points_s"] > 0
