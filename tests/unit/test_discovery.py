"""Discovery on concealed effects (tests/discovery_cases.py) and on untidy recordings.

Every case hides known effects in a realistic ISO 230-2 recording with AR(1) noise
and checks the verdict, the effects claimed (no more, no fewer), their parameters
(25 %; period 5 %; phases within 0.25 rad; a defect's centre within a quarter of
its width) and that the residual after is within 1.3 x the true noise.  Three
seeds per case, so a lucky draw cannot pass a wrong method.
"""

from __future__ import annotations

import dataclasses
import json
import math
import sys
from pathlib import Path
from typing import ClassVar

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from discovery_cases import CASES  # noqa: E402

from station.axis_model import read_axis_model  # noqa: E402
from station.discovery import discover, write_outputs  # noqa: E402
from station.discovery.synth import Campaign, linear_model, make_recording  # noqa: E402
from station.effects import Backlash, Effect, Scale  # noqa: E402

SEEDS = (1, 2, 3)
REL_TOL = 0.25
PERIOD_TOL = 0.05
PHASE_TOL_RAD = 0.25


def _check_parameters(found: dict, truth, case_name: str):
    for name, true_value in truth.parameters.items():
        got = found["parameters"][name]
        if name == "t_ref":
            assert got == true_value
        elif name == "phase":
            diff = math.remainder(got - true_value, 2 * math.pi)
            assert abs(diff) <= PHASE_TOL_RAD, (case_name, name, got, true_value)
        elif name == "centre":
            assert abs(got - true_value) <= 0.25 * truth.width, (case_name, name, got, true_value)
        elif name == "period":
            assert abs(got - true_value) <= PERIOD_TOL * abs(true_value), (case_name, name, got, true_value)
        else:
            assert abs(got - true_value) <= REL_TOL * abs(true_value), (case_name, name, got, true_value)
        if name != "t_ref":
            assert found["stderr"][name] > 0


@pytest.mark.parametrize("seed", SEEDS)
@pytest.mark.parametrize("case", CASES, ids=[c.name for c in CASES])
def test_concealed_effects_are_found(case, seed):
    c = case.with_seed(seed)
    model = c.model()
    rec = make_recording(model, c.hidden, c.campaign)
    report = discover(model, rec).report
    assert report["verdict"] == c.verdict, report["findings"]
    names = sorted(e["name"] for e in report["effects"])
    assert names == sorted(c.effects), report["selection"]
    by_name = {e["name"]: e for e in report["effects"]}
    for truth in c.hidden:
        _check_parameters(by_name[truth.name], truth, c.name)
    assert report["after"]["rms"] <= 1.3 * c.campaign.sigma
    if c.effects:
        assert report["after"]["white"]
        assert report["after"]["bic"] < report["before"]["bic"]
        assert all(e["explanation"] and e["delta_bic"] < 0 for e in report["effects"])
    else:
        assert report["effects"] == []


def test_drift_would_fool_an_iso_reversal_analysis():
    """The drift case really looks like backlash to ISO 230-2's reversal value B."""
    c = next(c for c in CASES if c.name == "drift_not_backlash").with_seed(1)
    model = c.model()
    rec = make_recording(model, c.hidden, c.campaign)
    r = rec.deviation - model.predict(rec)
    b = r[rec.direction > 0].mean() - r[rec.direction < 0].mean()
    se = c.campaign.sigma * np.sqrt(2.0 / (rec.direction.size / 2))
    assert abs(b) > 4 * se  # an ISO analysis would report a reversal value
    report = discover(model, rec).report
    assert [e["name"] for e in report["effects"]] == ["thermal_drift"]
    assert any(f["signature"] == "time" for f in report["findings"])


def test_contract_report_shape():
    c = CASES[0].with_seed(1)
    model = c.model()
    report = discover(model, make_recording(model, c.hidden, c.campaign)).report
    assert report["verdict"] in ("no-mismatch", "explained", "partly-explained")
    assert isinstance(report["noise_floor"], float)
    for stage in ("before", "after"):
        assert {"rms", "bic", "white"} <= set(report[stage])
        assert isinstance(report[stage]["white"], bool)
    for f in report["findings"]:
        assert f["signature"] in ("direction", "position", "periodic", "time", "temperature", "angle", "local")
        assert len(f["range"]) == 2 and f["description"]
    for e in report["effects"]:
        assert {"name", "parameters", "stderr", "delta_bic", "explanation"} <= set(e)
    json.dumps(report, allow_nan=False)


def test_outlier_from_blocked_beam_is_excluded_and_listed():
    model = linear_model()
    c = Campaign(seed=4)
    rec = make_recording(model, (Backlash(3.0),), c, outliers={37: 80.0})
    report = discover(model, rec).report
    assert [o["line"] for o in report["outliers"]] == [int(rec.line[37])]
    assert report["recording"]["rows_used"] == len(rec) - 1
    assert [e["name"] for e in report["effects"]] == ["backlash"]
    assert abs(report["effects"][0]["parameters"]["reversal"] - 3.0) < 0.75
    assert report["verdict"] == "explained"


def test_untidy_recording_no_time_no_temperature_uneven_runs_missing_target():
    model = linear_model()
    rec = make_recording(model, (Backlash(3.0), Scale(20.0)), Campaign(seed=5, time_zero=True))
    # run 5 stopped after its + pass; run 2 misses one target in the - direction
    keep = ~((rec.run == 5) & (rec.direction < 0))
    keep &= ~((rec.run == 2) & (rec.direction < 0) & (np.abs(rec.target - rec.target[3]) < 1e-9))
    rec = rec.subset(keep)
    report = discover(model, rec).report
    missing = {n["what"] for n in report["not_analysed"]}
    assert {"time", "temperature"} <= missing
    assert sorted(e["name"] for e in report["effects"]) == ["backlash", "scale"]
    amb = [set(a["effects"]) for a in report["ambiguities"]]
    assert {"backlash", "thermal_drift"} in amb      # no time stamps: drift not excluded
    assert {"scale", "thermal_expansion"} in amb     # no temperature: expansion not excluded
    assert all(a["separate_by"] for a in report["ambiguities"])


def test_found_model_replays_the_recording_within_noise(tmp_path):
    """The written model.toml is usable by discovery again and leaves nothing to find."""
    c = next(c for c in CASES if c.name == "backlash_and_scale").with_seed(2)
    model = c.model()
    rec = make_recording(model, c.hidden, c.campaign)
    write_outputs(discover(model, rec), tmp_path, plots=False)
    again = discover(read_axis_model(tmp_path / "model.toml"), rec).report
    assert again["verdict"] == "no-mismatch"
    assert again["effects"] == []


@dataclasses.dataclass(frozen=True)
class _Bend(Effect):
    """A parabolic error no library effect has (test-only, deliberately not registered)."""

    amplitude: float = 0.0
    name: ClassVar[str] = "test_bend"
    explanation: ClassVar[str] = "test only"

    def evaluate(self, ctx):
        return self.amplitude * ((ctx.x - 60.0) / 60.0) ** 2


def test_structure_outside_the_library_is_partly_explained_and_located():
    model = linear_model()
    report = discover(model, make_recording(model, (_Bend(3.0),), Campaign(seed=2))).report
    assert report["verdict"] == "partly-explained"
    remaining = [f for f in report["findings"] if f["stage"] == "after"]
    assert any(f["signature"] == "position" for f in remaining)
    assert report["after"]["rms"] > 1.3 * 0.5 or not report["after"]["white"]


def test_cli_writes_report_model_and_plots(tmp_path):
    model = linear_model()
    rec = make_recording(model, (Backlash(3.0),), Campaign(seed=6))
    rec.to_csv(tmp_path / "rec.csv")
    model.to_toml(tmp_path / "model.toml")
    from typer.testing import CliRunner

    from station.cli import app

    res = CliRunner().invoke(app, ["discover", "--model", str(tmp_path / "model.toml"),
                                   "--recording", str(tmp_path / "rec.csv"), "--out", str(tmp_path / "out")])
    assert res.exit_code == 0, res.output
    report = json.loads((tmp_path / "out" / "report.json").read_text())
    assert report["verdict"] == "explained"
    assert read_axis_model(tmp_path / "out" / "model.toml").curve.effects[0].name == "backlash"
    for png in ("residual_position.png", "residual_time.png", "residual_direction.png", "spectrum.png"):
        assert (tmp_path / "out" / png).stat().st_size > 1000


def test_cli_refuses_bad_input_with_line_and_column(tmp_path):
    from typer.testing import CliRunner

    from station.cli import app

    model = linear_model()
    rec = make_recording(model, (), Campaign(seed=7))
    text = rec.to_csv().splitlines()
    header_at = next(i for i, ln in enumerate(text) if ln.startswith("time_s"))
    fields = text[header_at + 3].split(",")
    fields[4] = "nan"
    text[header_at + 3] = ",".join(fields)
    (tmp_path / "rec.csv").write_text("\n".join(text) + "\n")
    model.to_toml(tmp_path / "model.toml")
    res = CliRunner().invoke(app, ["discover", "--model", str(tmp_path / "model.toml"),
                                   "--recording", str(tmp_path / "rec.csv"), "--out", str(tmp_path / "out")])
    assert res.exit_code != 0
    assert f"line {header_at + 4}" in res.output and "deviation" in res.output
    assert "Traceback" not in res.output
    res = CliRunner().invoke(app, ["discover", "--model", str(tmp_path / "missing.toml"),
                                   "--recording", str(tmp_path / "rec.csv"), "--out", str(tmp_path / "out")])
    assert res.exit_code != 0 and "missing.toml" in res.output
