"""``station bench vision``: its statistics (the ratio's bootstrap interval) and one small run."""

import numpy as np
import pytest

from station.vision.scoring import ratio_of_medians_ci


def test_ratio_interval_covers_the_true_ratio_and_narrows_with_more_frames():
    """Per-frame errors with a known ratio of medians (baseline 5x ours): the interval
    holds 5 and is narrower for ten times the frames."""
    rng = np.random.default_rng(3)

    def frames(n):
        counts = rng.integers(0, 4, n)
        ours = [list(0.02 * rng.standard_normal(k)) for k in counts]
        base = [list(0.10 * rng.standard_normal(k)) for k in counts]
        return base, ours

    lo, hi = ratio_of_medians_ci(*frames(40), draws=1000)
    lo_big, hi_big = ratio_of_medians_ci(*frames(400), draws=1000)
    assert lo < 5.0 < hi
    assert lo_big < 5.0 < hi_big
    assert (hi_big - lo_big) < 0.5 * (hi - lo)


def test_ratio_interval_resamples_whole_frames():
    """A frame's holes share its condition: one frame with a huge error on every hole
    is one unit of the resampling, so the interval stays near the clean ratio when it is
    left out of a draw, and the spread comes from frames, not from single holes."""
    ours = [[0.01, -0.01], [0.01, 0.01], [0.01]] * 10 + [[1.0] * 30]
    base = [[0.05, 0.05], [-0.05, 0.05], [0.05]] * 10 + [[0.05] * 30]
    lo, hi = ratio_of_medians_ci(base, ours, draws=500)
    # with the bad frame drawn the median of ours may jump to 1.0 (ratio 0.05); without it
    # the ratio is 5: a per-hole bootstrap would never see 0.05
    assert lo == pytest.approx(0.05, rel=1e-6) and hi == pytest.approx(5.0, rel=1e-6)


def test_ratio_interval_refuses_mismatched_frames():
    with pytest.raises(ValueError, match="same frames"):
        ratio_of_medians_ci([[0.1]], [[0.1], [0.2]])


def test_bench_run_scores_every_method_on_the_same_frames():
    from station.bench.vision import run

    calls = []
    r = run(frames=4, seed=1000, progress=lambda: calls.append(1))
    assert len(calls) == 4 * 4  # rendering + 3 methods, one call per frame each
    assert set(r["methods"]) == {"ours", "hough_gradient_alt", "contours_fit_ellipse"}
    holes = r["whole_holes"]
    assert holes > 0
    for m in r["methods"].values():
        assert m["holes_measured"] + m["misses"] == holes
    lo, hi = r["diameter_accuracy_ratio_ci95"]
    assert lo <= r["diameter_accuracy_ratio_vs_better_baseline"] <= hi
    assert r["better_baseline"]["diameter"] in ("hough_gradient_alt", "contours_fit_ellipse")
    # the tails' ratios are of the same two methods as the headline's
    by_stat = r["accuracy_ratios_by_statistic"]
    assert by_stat["median"]["diameter"] == pytest.approx(r["diameter_accuracy_ratio_vs_better_baseline"])
    better = r["methods"][r["better_baseline"]["diameter"]]
    assert by_stat["p90"]["diameter"] == pytest.approx(
        better["p90_diameter_err_px"] / r["methods"]["ours"]["p90_diameter_err_px"])
    # ours states its own uncertainties; the baselines do not
    assert r["methods"]["ours"]["holes_with_u"] == r["methods"]["ours"]["holes_measured"]
    assert 0.0 <= r["methods"]["ours"]["diameter_within_2u"] <= 1.0
    assert "holes_with_u" not in r["methods"]["hough_gradient_alt"]


def test_scoring_judges_stated_uncertainties_by_the_errors():
    from station.vision.scoring import score_frame

    truths = [(100.0, 100.0, 40.0, False), (300.0, 200.0, 30.0, False), (5.0, 50.0, 30.0, True)]
    dets = [
        (100.03, 99.98, 40.10, False, 0.04, 0.01, 0.01),  # diameter 2.5 u off, x 3 u, y 2 u
        (300.00, 200.01, 29.99, False, 0.02, 0.02, 0.02),  # all within 1 u
        (5.5, 50.0, 29.0, True, None, None, None),  # a cut hole: no uncertainty, not judged
    ]
    s = score_frame(truths, dets)
    assert s.diameter_z == pytest.approx([2.5, -0.5])
    assert s.centre_z == pytest.approx([3.0, -2.0, 0.0, 0.5])
    summary = s.summary()
    assert summary["diameter_within_2u"] == pytest.approx(0.5)
    assert summary["centre_within_2u"] == pytest.approx(0.75)
    assert summary["holes_with_u"] == 2
    # |diameter errors| 0.10 and 0.01: RMS and the 90th percentile (linear interpolation)
    assert summary["rms_diameter_err_px"] == pytest.approx(np.sqrt((0.10**2 + 0.01**2) / 2))
    assert summary["p90_diameter_err_px"] == pytest.approx(0.01 + 0.9 * 0.09)
    # detections without uncertainties leave the figures out
    plain = score_frame(truths, [d[:4] for d in dets]).summary()
    assert "diameter_within_2u" not in plain


def test_the_benches_render_their_frames_under_the_lens_spread_asked_for():
    """``--psf-disc`` / ``--psf-smear`` / ``--psf-smear-deg`` reach the renderer
    (``sim.camera.render.psf_kernel``) in both benches and are reported; without them the
    benches ask for no spread (that the frames are then the old ones, byte for byte, is
    the renderer's sha test in test_defects.py)."""
    import json

    from typer.testing import CliRunner

    from station.bench.psf import psf_overrides
    from station.cli import app

    assert psf_overrides(0.0, 0.0, 0.0) == {}
    runner = CliRunner()
    plain = json.loads(runner.invoke(app, ["bench", "vision", "--frames", "4", "--seed", "1000", "--json"]).stdout)
    res = runner.invoke(app, ["bench", "vision", "--frames", "4", "--seed", "1000", "--psf-disc", "3",
                              "--psf-smear", "2", "--psf-smear-deg", "45", "--json"])
    assert res.exit_code == 0, res.output
    spread = json.loads(res.stdout)
    assert plain["psf"] == {}
    assert spread["psf"] == {"psf_disc_px": 3.0, "psf_smear_px": 2.0, "psf_smear_deg": 45.0}
    assert spread["whole_holes"] == plain["whole_holes"] > 0
    # the same holes, measured on other pixels
    assert spread["methods"]["ours"]["rms_diameter_err_px"] != plain["methods"]["ours"]["rms_diameter_err_px"]
    res = runner.invoke(app, ["bench", "defects", "--frames", "1", "--seed", "91010", "--twin-frames", "0",
                              "--psf-disc", "2", "--json"])
    assert res.exit_code == 0, res.output
    assert json.loads(res.stdout)["psf"] == {"psf_disc_px": 2.0}


def test_the_defect_bench_draws_pores_on_scratches_when_asked(monkeypatch):
    """``station bench defects --pores-on-scratches P`` reaches the twin's draw
    (``random_defect_frame``, ``random_defects``) for the frames with defects and is
    reported; its default asks for none (every defect clear of the others)."""
    import json

    from typer.testing import CliRunner

    import sim.camera.defects as twin
    from station.cli import app

    asked = []
    draw = twin.random_defect_frame

    def recording(seed, kinds=None, **kw):
        asked.append((kinds, kw.get("pores_on_scratches", 0.0)))
        return draw(seed, kinds, **kw)

    monkeypatch.setattr(twin, "random_defect_frame", recording)
    runner = CliRunner()
    for flag, share in (([], 0.0), (["--pores-on-scratches", "1"], 1.0)):
        asked.clear()
        res = runner.invoke(app, ["bench", "defects", "--frames", "1", "--seed", "4300003", "--twin-frames", "0",
                                  "--json", *flag])
        assert res.exit_code == 0, res.output
        assert json.loads(res.stdout)["pores_on_scratches"] == share
        assert [p for kinds, p in asked if kinds is None] == [share]  # the frame with defects
    on = twin.random_defect_frame(4300003, None, pores_on_scratches=1.0).defects
    off = twin.random_defect_frame(4300003, None).defects
    assert {"pore", "scratch"} <= {d.kind for d in off}
    assert [(d.kind, round(d.x_px, 3)) for d in on] != [(d.kind, round(d.x_px, 3)) for d in off]
    res = runner.invoke(app, ["bench", "defects", "--frames", "1", "--pores-on-scratches", "1.5", "--json"])
    assert res.exit_code != 0
