"""The effect vocabulary, recordings and axis models (the discovery contract's files)."""

from __future__ import annotations

import numpy as np
import pytest

from station.axis_model import AxisModelError, axis_model_from_dict, read_axis_model
from station.effects import (
    Backlash,
    Eccentricity,
    EffectSpecError,
    ErrorCurve,
    EvalContext,
    Offset,
    Periodic,
    Scale,
    ThermalDrift,
    ThermalExpansion,
    effect_from_dict,
)
from testkit.fuzz import AXIS_MODEL_SEED, RECORDING_SEED
from station.recording import RecordingError, parse_recording

# the same files the fuzzer starts from (one copy of the seed data)
GOOD = RECORDING_SEED


# ---------------------------------------------------------------- vocabulary formulas (the spec's table)
def test_vocabulary_formulas_match_the_contract():
    x = np.array([0.0, 30.0, 90.0])
    s = np.array([1.0, -1.0, 1.0])
    t = np.array([0.0, 600.0, 1800.0])
    T = np.array([20.0, 22.0, 25.0])
    lin = EvalContext.make(x, "linear", s, t, T)
    rot = EvalContext.make(x, "rotary", s, t, T)
    assert Offset(2.5).evaluate(lin) == pytest.approx([2.5] * 3)
    assert Scale(10.0).evaluate(lin) == pytest.approx(10e-6 * 1000 * x)
    assert Scale(10.0).evaluate(rot) == pytest.approx(10e-6 * 3600 * x)
    assert Backlash(4.0).evaluate(lin) == pytest.approx([2.0, -2.0, 2.0])
    assert Periodic(period=5.0, amplitude=1.5, phase=0.3).evaluate(lin) == pytest.approx(1.5 * np.sin(2 * np.pi * x / 5 + 0.3))
    assert ThermalExpansion(11.5).evaluate(lin) == pytest.approx(11.5e-6 * 1000 * x * (T - 20))
    assert ThermalExpansion(11.5, t_ref=22.0).evaluate(lin)[1] == pytest.approx(0.0)
    assert ThermalDrift(3.0, 600.0).evaluate(lin) == pytest.approx(3.0 * (1 - np.exp(-t / 600)))
    assert Eccentricity(4.0, 0.5).evaluate(rot) == pytest.approx(4.0 * np.sin(np.radians(x) + 0.5))


def test_backlash_is_iso_reversal():
    """mean(+1) - mean(-1) = reversal: ISO 230-2's B for a pure backlash."""
    x = np.repeat(np.linspace(0, 100, 6), 2)
    s = np.tile([1.0, -1.0], 6)
    d = Backlash(3.7).evaluate(EvalContext.make(x, "linear", s))
    assert d[s > 0].mean() - d[s < 0].mean() == pytest.approx(3.7)


def test_missing_context_contributes_nothing():
    ctx = EvalContext.make(np.array([10.0, 20.0]))
    for e in (Backlash(4.0), ThermalExpansion(10.0), ThermalDrift(2.0, 100.0)):
        assert e.evaluate(ctx) == pytest.approx([0.0, 0.0])


def test_jacobian_of_effects():
    ctx = EvalContext.make(np.linspace(0, 20, 7))
    e = Periodic(period=4.0, amplitude=2.0, phase=0.1)
    J = e.jacobian(ctx)
    x = ctx.x
    arg = 2 * np.pi * x / 4.0 + 0.1
    assert J[:, 1] == pytest.approx(np.sin(arg), abs=1e-7)  # d/d amplitude
    assert J[:, 2] == pytest.approx(2.0 * np.cos(arg), abs=1e-6)  # d/d phase
    assert J[:, 0] == pytest.approx(-2.0 * np.cos(arg) * 2 * np.pi * x / 16.0, abs=1e-5)  # d/d period


def test_error_curve_interpolation_and_rotary_wrap():
    lin = ErrorCurve.table([0, 10, 20], [0, 5, 3])
    assert lin.evaluate([-5, 5, 15, 30]) == pytest.approx([0, 2.5, 4, 3])  # flat outside
    rot = ErrorCurve.table([0, 120, 240], [0, 12, 24], kind="rotary")
    # between 240 and 360 (= 0) it returns to 0: modulo 360
    assert rot.evaluate([300.0, 660.0, -60.0]) == pytest.approx([12.0, 12.0, 12.0])
    with_eff = lin.with_effects(Offset(1.0), Backlash(2.0))
    assert with_eff.evaluate([5.0, 5.0], direction=[1, -1]) == pytest.approx([4.5, 2.5])


def test_effect_from_dict_refuses_bad_specs():
    assert effect_from_dict({"name": "backlash", "reversal": 4}) == Backlash(4.0)
    with pytest.raises(EffectSpecError, match="unknown effect 'wobble'"):
        effect_from_dict({"name": "wobble"}, "m.toml: effects[0]")
    with pytest.raises(EffectSpecError, match="no parameter 'size'"):
        effect_from_dict({"name": "backlash", "size": 1})
    with pytest.raises(EffectSpecError, match="not a number"):
        effect_from_dict({"name": "offset", "value": "big"})


# ---------------------------------------------------------------- recordings
def test_recording_parses_columns_metadata_and_extras():
    r = parse_recording(GOOD, "rec.csv")
    assert r.metadata == {"axis": "Z", "kind": "linear"}
    assert r.kind == "linear" and len(r) == 4
    assert list(r.direction) == [1, 1, -1, -1]
    assert r.temperature_c is not None and r.temperature_c[-1] == 20.3
    assert r.extra["note"] == ["a", "b", "", "c"]
    assert list(r.line) == [4, 5, 6, 7]
    again = parse_recording(r.to_csv(), "again.csv")
    assert np.array_equal(again.deviation, r.deviation) and again.extra == r.extra


@pytest.mark.parametrize(
    "mutate, line, column",
    [
        (lambda t: t.replace("time_s,run", "time,run"), 3, "time_s"),
        (lambda t: t.replace("1.0,1,+1,60.0,3.2", "1.0,1,+1,60.0,abc"), 5, "deviation"),
        (lambda t: t.replace("1.0,1,+1,60.0,3.2", "1.0,1,+1,60.0,nan"), 5, "deviation"),
        (lambda t: t.replace("2.0,1,-1", "0.5,1,-1"), 6, "time_s"),
        (lambda t: t.replace("2.0,1,-1", "2.0,1,0"), 6, "direction"),
        (lambda t: t.replace("3.0,1,-1", "3.0,x,-1"), 7, "run"),
    ],
)
def test_bad_recordings_name_line_and_column(mutate, line, column):
    with pytest.raises(RecordingError) as exc:
        parse_recording(mutate(GOOD), "rec.csv")
    assert exc.value.line == line and exc.value.column == column
    assert f"rec.csv, line {line}, column '{column}'" in str(exc.value)


def test_recording_without_rows_or_with_short_row():
    with pytest.raises(RecordingError, match="no data rows"):
        parse_recording("time_s,run,direction,target,deviation\n", "r.csv")
    with pytest.raises(RecordingError, match="line 2: 3 fields"):
        parse_recording("time_s,run,direction,target,deviation\n0,1,+1\n", "r.csv")


# ---------------------------------------------------------------- axis models
MODEL = AXIS_MODEL_SEED


def test_axis_model_round_trip_and_predict(tmp_path):
    p = tmp_path / "m.toml"
    p.write_text(MODEL)
    m = read_axis_model(p)
    assert m.noise_sigma == 0.5 and m.curve.effects == (Backlash(4.0),)
    r = parse_recording(GOOD, "rec.csv")
    assert m.predict(r) == pytest.approx([2.0, 8.0, 4.0, -2.0])
    out = tmp_path / "out.toml"
    m.with_effects(Scale(2.0)).to_toml(out)
    m2 = read_axis_model(out)
    assert m2.curve.effects == (Backlash(4.0), Scale(2.0)) and m2.name == "Z"


def test_axis_model_errors_name_the_field():
    with pytest.raises(AxisModelError, match=r"m.toml: \[axis\] kind"):
        axis_model_from_dict({"axis": {"name": "Z", "kind": "spiral"}}, "m.toml")
    with pytest.raises(AxisModelError, match="baseline.deviation"):
        axis_model_from_dict({"axis": {"kind": "linear"}, "baseline": {"target": [0, 1], "deviation": [0, "x"]}}, "m.toml")
    with pytest.raises(AxisModelError, match=r"effects\[0\] 'eccentricity' does not apply to a linear axis"):
        axis_model_from_dict({"axis": {"kind": "linear"}, "effects": [{"name": "eccentricity", "amplitude": 1}]}, "m.toml")
