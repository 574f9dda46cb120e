"""Structure outside the vocabulary is described, never misnamed (issue 20, item 4).

Each recording hides one structure no vocabulary effect describes -- a step in the
scale (a grating segment joint), a curvature, a sawtooth, a reversal that grows along
the travel or over the campaign -- in realistic ISO 230-2 runs with AR(1) noise
(``station.discovery.synth.Structure``).  Discovery must not claim a vocabulary effect
for it: the structure comes back as a located, described finding with the verdict
``partly-explained``, or, for a step, as a ``step`` effect placed where the joint is.
Real vocabulary effects must still be claimed.  Fixed seeds, several per case.
"""

from __future__ import annotations

import numpy as np
import pytest

from station.axis_model import read_axis_model
from station.discovery import discover, write_outputs
from station.discovery.synth import Campaign, Structure, linear_model, make_recording, with_structure
from station.effects import Backlash, EvalContext, Periodic, Step, effect_from_dict

SIGMA = 0.5
DENSE = dict(dense_runs=2, dense_span=(30.0, 70.0), dense_step=0.5)


def recording(structure: Structure, seed: int, **campaign):
    model = linear_model(SIGMA)
    c = Campaign(sigma=SIGMA, phi=0.3, seed=seed, **campaign)
    return model, with_structure(make_recording(model, (), c), structure)


def outside(report: dict) -> list[dict]:
    """Findings that describe structure outside the vocabulary."""
    return [f for f in report["findings"] if f.get("outside_vocabulary")]


# ------------------------------------------------------------------------------------------ step

def test_step_effect_formula_and_model_file():
    ctx = EvalContext.make(np.array([10.0, 63.0, 90.0]))
    assert Step(63.0, 2.4).evaluate(ctx) == pytest.approx([0.0, 2.4, 2.4])
    assert effect_from_dict({"name": "step", "position": 63.0, "height": 2.4}) == Step(63.0, 2.4)
    assert Step.explanation and "joint" in Step.explanation


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_step_is_not_called_periodic_but_a_step_where_the_joint_is(seed):
    """The reported defect: a step of the scale came back as a periodic effect."""
    x0, h = 63.0, 6 * SIGMA
    model, rec = recording(Structure("step", "step", h, position=x0), seed)
    report = discover(model, rec).report
    names = [e["name"] for e in report["effects"]]
    assert "periodic" not in names, report["effects"]
    assert names == ["step"], report["selection"]
    step = report["effects"][0]
    pos, se = step["parameters"]["position"], step["stderr"]["position"]
    # placed in the gap between the targets around the joint, and says how well it knows it
    assert abs(pos - x0) <= 1.96 * se, (pos, se)
    assert se < 12.0                                  # a gap between targets, not the travel
    assert step["parameters"]["height"] == pytest.approx(h, abs=4 * step["stderr"]["height"])
    assert report["verdict"] == "explained"
    assert report["after"]["rms"] <= 1.3 * SIGMA


def test_a_step_written_to_the_model_replays_the_recording(tmp_path):
    model, rec = recording(Structure("step", "step", -4 * SIGMA, position=47.0), 4)
    write_outputs(discover(model, rec), tmp_path, plots=False)
    again = discover(read_axis_model(tmp_path / "model.toml"), rec).report
    assert again["verdict"] == "no-mismatch", again["effects"]


def test_a_step_is_located_by_the_findings_before_any_effect():
    model, rec = recording(Structure("step", "step", 5 * SIGMA, position=81.0), 5)
    report = discover(model, rec).report
    located = [f for f in report["findings"] if f["stage"] == "before" and f["range"][0] <= 81.0 <= f["range"][1]
               and f["range"][1] - f["range"][0] < 30.0]
    assert located, report["findings"]
    assert any("step" in f["description"] for f in located)


# ------------------------------------------------------------------------------------- curvature

@pytest.mark.parametrize("variant,seed", [("quadratic", 1), ("quadratic_from_zero", 2), ("cubic", 3),
                                          ("cubic_from_zero", 4), ("quadratic_cubic", 5)])
def test_curvature_is_a_finding_not_an_offset_scale_or_sine(variant, seed):
    model, rec = recording(Structure("curvature", variant, 8 * SIGMA), seed)
    report = discover(model, rec).report
    assert report["effects"] == [], report["selection"]
    assert report["verdict"] == "partly-explained"
    found = outside(report)
    assert [f["signature"] for f in found] == ["position"], report["findings"]
    assert found[0]["range"] == [0.0, 120.0]
    assert "curvature" in found[0]["description"] and "um" in found[0]["description"]


def test_small_curvature_with_a_real_backlash_keeps_the_backlash_only():
    model = linear_model(SIGMA)
    rec = make_recording(model, (Backlash(3.0),), Campaign(sigma=SIGMA, phi=0.3, seed=6))
    rec = with_structure(rec, Structure("curvature", "quadratic", 4 * SIGMA))
    report = discover(model, rec).report
    assert [e["name"] for e in report["effects"]] == ["backlash"], report["selection"]
    assert report["effects"][0]["parameters"]["reversal"] == pytest.approx(3.0, abs=0.6)
    assert report["verdict"] == "partly-explained"
    assert [f["signature"] for f in outside(report)] == ["position"]


# ---------------------------------------------------------------------- non-sinusoidal periodic

@pytest.mark.parametrize("variant,period,seed", [("sawtooth", 9.0, 1), ("sawtooth", 17.0, 2), ("square", 12.0, 3),
                                                 ("triangle", 14.0, 4)])
def test_non_sinusoidal_periodic_error_is_not_claimed_as_a_sine(variant, period, seed):
    model, rec = recording(Structure("nonsine_periodic", variant, 10 * SIGMA, period=period, phase=0.3), seed,
                           **DENSE)
    report = discover(model, rec).report
    assert report["effects"] == [], report["selection"]
    assert report["verdict"] == "partly-explained"
    found = [f for f in outside(report) if f["signature"] == "periodic"]
    assert found and abs(found[0]["period"] - period) <= 0.02 * period, report["findings"]
    assert "not a sine" in found[0]["description"] or "non-sinusoidal" in found[0]["description"]


def test_a_real_sine_is_still_claimed_as_periodic():
    model = linear_model(SIGMA)
    for seed in (1, 2):
        rec = make_recording(model, (Periodic(6.0, 2 * SIGMA, 0.4),), Campaign(sigma=SIGMA, phi=0.3, seed=seed, **DENSE))
        report = discover(model, rec).report
        assert [e["name"] for e in report["effects"]] == ["periodic"], report["selection"]
        assert report["effects"][0]["parameters"]["period"] == pytest.approx(6.0, rel=0.02)
        assert report["verdict"] == "explained"
        assert outside(report) == []


# ----------------------------------------------------------------------------- growing hysteresis

@pytest.mark.parametrize("variant,seed", [("with_position", 1), ("with_position", 2), ("with_distance", 3),
                                          ("with_distance", 4)])
def test_growing_hysteresis_is_not_a_constant_backlash(variant, seed):
    model, rec = recording(Structure("growing_hysteresis", variant, 8 * SIGMA), seed)
    report = discover(model, rec).report
    assert report["effects"] == [], report["selection"]
    assert report["verdict"] == "partly-explained"
    found = outside(report)
    assert [f["signature"] for f in found] == ["direction"], report["findings"]
    assert "reversal" in found[0]["description"]


def test_a_real_backlash_is_still_claimed():
    model = linear_model(SIGMA)
    for seed in (1, 2):
        rec = make_recording(model, (Backlash(4 * SIGMA),), Campaign(sigma=SIGMA, phi=0.3, seed=seed))
        report = discover(model, rec).report
        assert [e["name"] for e in report["effects"]] == ["backlash"], report["selection"]
        assert report["verdict"] == "explained"


# ------------------------------------------------------------------------------------------- bench

def test_bench_reports_out_of_vocabulary_claims_by_kind():
    from station.bench.discovery import OOV_KINDS, run_oov

    res = run_oov(per_kind_size=1, seed=3)
    assert set(res["by_kind"]) == set(OOV_KINDS)
    assert res["datasets"] == 4 * len(res["sizes_in_noise_units"])
    for v in res["by_kind"].values():
        assert 0.0 <= v["false_claim_rate"] <= 1.0 and 0.0 <= v["located"] <= 1.0
        assert sum(v["verdicts"].values()) == v["datasets"]
