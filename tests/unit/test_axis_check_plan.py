"""The station's own check of Z (station.checks.axis), without twins: the plan fed by a
small stand-in for the engine and a world curve, the contract's files, discovery on
them, and the changes of EZZ it proposes applied to the station's model."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from drivers.interfaces import EncoderReading, EncoderStatus
from station.axis_model import read_axis_model
from station.checks.axis import (
    AxisCheckSettings,
    apply_motion_change,
    axis_changes,
    axis_check_plan,
    axis_proposal,
    check_stroke,
    check_targets,
    expected_change_um,
    grating_residual_change_um,
    left_out,
    motion_term,
    parse_motion_term,
    run_discovery,
)
from station.effects import Backlash
from station.inspection.scan import predicted_carriage_mm
from station.kinematics.model import load_model
from station.monitor.proposals import Change, ProposalError, apply_changes
from station.parts import load_part
from station.recording import read_recording
from station.sequencer import messages as m

GOOD = EncoderStatus(referenced=True, signal_low=False, overspeed=False, hardware_error=False)


def drive(plan, curve, sigma_um=0.0, seed=0, bad_at=None):
    """Carry out a plan on a stand-in Z: the carriage is the command plus ``curve``
    (um) in the direction of the last move, plus a normal draw per move (ISO 230-2's
    repeatability); C reads 0. Returns (the plan's value, moves, directions seen at
    each reading)."""
    rng = np.random.default_rng(seed)
    z, direction, t, draw = 0.0, +1, 0.0, 0.0
    moves, seen = [], []
    result = None
    while True:
        try:
            msg = plan.send(result)
        except StopIteration as done:
            return done.value, moves, seen
        result = None
        if isinstance(msg, m.Move):
            assert msg.axis == "Z", "the check moves Z only"
            if msg.position != z:
                direction = 1 if msg.position > z else -1
            z = msg.position
            moves.append((z, direction))
            t += 0.5
            draw = rng.normal(0.0, sigma_um) if sigma_um > 0 else 0.0
        elif isinstance(msg, m.ReadAxis):
            result = 0.0 if msg.axis == "C" else z
        elif isinstance(msg, m.ReadEncoder):
            t += 0.01
            seen.append(direction)
            status = GOOD if bad_at is None or abs(z - bad_at) > 1e-9 else replace(GOOD, signal_low=True)
            result = EncoderReading(z + (curve.evaluate([z], [direction])[0] + draw) * 1e-3, t, status)
        elif isinstance(msg, m.Settle):
            t += msg.seconds


@pytest.fixture(scope="module")
def model():
    return load_model()


def worn_curve(model, extra_um):
    """The world: the station's EZZ with ``extra_um`` more lost motion."""
    return model.motions_of("Z").z.with_effects(Backlash(reversal=extra_um))


def test_the_stroke_covers_the_family_and_the_targets_are_spread_irregularly(model):
    fam = load_part("ZDZG-22.2-12.3851")
    lo, hi = check_stroke(model, fam)
    # from the overrun above the travel's start (the lower overrun ends at home) past
    # the deepest search zone (85.29 + 0.5 mm) by the margin
    assert lo == 1.0 and hi == 91.0
    t = check_targets(lo, hi)
    assert len(t) == 11 and t[0] == lo and t[-1] == hi and t == sorted(t)
    p = (hi - lo) / 10
    steps = np.diff(t)
    assert np.all(steps > 0.5 * p) and np.ptp(steps) > 0.1 * p  # irregular, never bunched
    assert t == check_targets(lo, hi), "every check uses the same targets"
    assert check_targets(lo, hi, AxisCheckSettings(irregular=False)) == [round(v, 3) for v in np.linspace(1, 91, 11)]
    with pytest.raises(ValueError):
        AxisCheckSettings(targets=2)


def test_the_plan_is_an_iso_230_2_cycle_with_reversals_beyond_the_targets(model):
    s = AxisCheckSettings(runs=2, targets=5, readings=3)
    targets = check_targets(10.0, 50.0, s)
    data, moves, seen = drive(axis_check_plan(model, targets, s), worn_curve(model, 0.0))
    assert len(data.points) == 2 * 2 * 5 and data.c_deg == 0.0
    # each target is reached moving in its run's direction, and read so
    assert all(d == p.direction for d, p in zip(seen[::3], data.points))
    assert [p.direction for p in data.points[:10]] == [1] * 5 + [-1] * 5
    assert [p.target_mm for p in data.points[:10]] == targets + targets[::-1]
    # the reversals are made beyond the end targets by the overrun
    positions = [z for z, _ in moves]
    assert positions[0] == pytest.approx(targets[0] - s.overrun_mm)
    assert positions.count(targets[-1] + s.overrun_mm) == 2 and positions.count(targets[0] - s.overrun_mm) == 2
    # the model's prediction, in the approach direction: its 1.5 um lost motion shows
    for p in data.points:
        assert p.predicted_mm == predicted_carriage_mm(model, p.target_mm, p.direction)
        assert p.deviation_um == pytest.approx(0.0, abs=1e-6)
    up, down = data.points[0], data.points[-1]
    assert up.model_um - down.model_um == pytest.approx(1.5, abs=1e-9)
    assert all(b.time_s >= a.time_s for a, b in zip(data.points, data.points[1:]))


def test_a_flagged_reading_is_not_a_reading(model):
    s = AxisCheckSettings(runs=1, targets=5, readings=2)
    targets = check_targets(10.0, 50.0, s)
    data, _, _ = drive(axis_check_plan(model, targets, s), worn_curve(model, 0.0), bad_at=targets[2])
    assert len(data.points) == 8 and targets[2] not in [p.target_mm for p in data.points]


def test_discovery_on_the_contract_files_names_the_grown_lost_motion(model, tmp_path):
    s = AxisCheckSettings()
    targets = check_targets(1.0, 91.0, s)
    data, _, _ = drive(axis_check_plan(model, targets, s), worn_curve(model, 3.0), sigma_um=0.3, seed=4)
    d, files = run_discovery(data, model, 0.3, tmp_path, plots=False)
    assert {p.name for p in files} >= {"recording.csv", "axis_model.toml", "report.json", "model.toml"}
    # the contract's files: deviation is actual minus commanded; the model is the station's EZZ
    rec = read_recording(tmp_path / "recording.csv")
    am = read_axis_model(tmp_path / "axis_model.toml")
    assert rec.axis == "Z" and rec.kind == "linear" and len(rec) == 66
    assert am.noise_sigma == 0.3 and am.curve == model.motions_of("Z").z
    resid = rec.deviation - am.predict(rec)
    assert np.allclose(resid, [p.deviation_um for p in data.points], atol=1e-5)
    assert np.allclose(rec.deviation - np.array(rec.extra["model"], dtype=float), resid, atol=1e-5)
    r = d.report
    assert r["verdict"] == "explained", r["findings"]
    (eff,) = r["effects"]
    assert eff["name"] == "backlash" and abs(eff["parameters"]["reversal"] - 3.0) < 4 * eff["stderr"]["reversal"] + 0.05
    changes = axis_changes(r, model)
    assert [c.term for c in changes] == ["motion.Z.EZZ.backlash"]
    assert changes[0].delta == pytest.approx(eff["parameters"]["reversal"])
    # the proposal: evidence per target and direction, and the holes' readings do not move
    p = axis_proposal(r, data, model, "default-station@x", {"hole_1": 71.03, "hole_2": 85.19}, 32.0)
    assert p is not None and p.changes == changes and len(p.evidence) == 22
    assert all(abs(v) < 0.01 for v in p.expected_change_um.values()), p.expected_change_um
    assert "backlash" in p.reason and "lost motion" in p.changes[0].why
    # with the change the model predicts what the grating read
    new = apply_changes(model, changes)
    after = [(p.grating_mm - predicted_carriage_mm(new, p.target_mm, p.direction)) * 1e3 for p in data.points]
    assert math.sqrt(np.mean(np.square(after))) < 0.45 < r["before"]["rms"]


def test_a_model_that_agrees_proposes_nothing(model, tmp_path):
    s = AxisCheckSettings()
    data, _, _ = drive(axis_check_plan(model, check_targets(1.0, 91.0, s), s), worn_curve(model, 0.0), 0.3, seed=4)
    d, _ = run_discovery(data, model, 0.3, tmp_path, plots=False)
    assert d.report["verdict"] == "no-mismatch", d.report["findings"]
    assert axis_changes(d.report, model) == [] and axis_proposal(d.report, data, model, "v", {"h": 71.0}) is None


def test_a_backlash_change_adds_to_the_models_lost_motion(model):
    new = apply_motion_change(model, Change("motion.Z.EZZ.backlash", 2.0))
    (b,) = new.motions_of("Z").z.effects
    assert b.name == "backlash" and b.reversal == pytest.approx(3.5)
    assert model.motions_of("Z").z.effects[0].reversal == 1.5, "a new model, the old one unchanged"
    for z in (10.0, 71.03):
        up = predicted_carriage_mm(new, z, +1) - predicted_carriage_mm(model, z, +1)
        down = predicted_carriage_mm(new, z, -1) - predicted_carriage_mm(model, z, -1)
        assert up * 1e3 == pytest.approx(1.0) and down * 1e3 == pytest.approx(-1.0)
    # through the proposals' own Change.apply (the dispatch of motion terms)
    assert apply_changes(model, [Change("motion.Z.EZZ.backlash", 2.0)]).motions == new.motions


def test_effects_with_a_shape_are_added_then_merged(model):
    term = motion_term("periodic", {"period": 5.0, "phase": 0.3})
    assert term == "motion.Z.EZZ.periodic(period=5.0,phase=0.3)"
    assert parse_motion_term(term) == ("Z", "EZZ", "periodic", {"period": 5.0, "phase": 0.3})
    one = apply_motion_change(model, Change(term, 0.4))
    two = apply_motion_change(one, Change(term, 0.2))
    per = [e for e in two.motions_of("Z").z.effects if e.name == "periodic"]
    assert len(per) == 1 and per[0].amplitude == pytest.approx(0.6) and per[0].period == 5.0
    other = apply_motion_change(two, Change(motion_term("periodic", {"period": 2.5, "phase": 0.3}), 0.1))
    assert len([e for e in other.motions_of("Z").z.effects if e.name == "periodic"]) == 2
    sc = apply_motion_change(model, Change("motion.Z.EZZ.scale", 4.0))
    # 4 ppm at 50 mm: 0.2 um on the carriage, either way
    assert (predicted_carriage_mm(sc, 50.0) - predicted_carriage_mm(model, 50.0)) * 1e3 == pytest.approx(0.2)


@pytest.mark.parametrize("term", [
    "motion.Z.EZZ.thermal_drift(tau=600.0)",  # a time effect: zero for a command
    "motion.Z.EQZ.backlash",                   # no such error motion
    "motion.J.EZJ.backlash",                   # J has no joint
    "motion.Q.EZQ.backlash",                   # no such body
    "motion.Z.EZZ.nonsense",
    "motion.Z.EZZ.periodic(period=five)",
    "motion.Z.EZZ",
])
def test_changes_that_are_not_motion_effects_are_refused(model, term):
    with pytest.raises(ProposalError):
        apply_motion_change(model, Change(term, 1.0))


def test_time_and_temperature_effects_are_reported_not_proposed(model):
    report = {"verdict": "partly-explained", "effects": [
        {"name": "thermal_drift", "parameters": {"amplitude": 1.0, "tau": 600.0}, "stderr": {}},
        {"name": "scale", "parameters": {"ppm": 3.0}, "stderr": {"ppm": 0.2}, "explanation": "longer"}]}
    assert [c.term for c in axis_changes(report, model)] == ["motion.Z.EZZ.scale"]
    assert left_out(report) == ["thermal_drift"]
    assert axis_changes({"verdict": "no-mismatch", "effects": report["effects"]}, model) == []


def test_a_change_of_z_positioning_does_not_move_the_holes_but_the_grating_chart(model):
    holes = {"hole_1": 71.03, "hole_2": 85.19}
    for change in (Change("motion.Z.EZZ.backlash", 4.0), Change("motion.Z.EZZ.scale", 10.0)):
        new = apply_changes(model, [change])
        assert all(abs(v) < 0.01 for v in expected_change_um(model, new, holes).values())
        chart = grating_residual_change_um(model, new, holes)
        for h, z in holes.items():
            ezz = (predicted_carriage_mm(new, z) - predicted_carriage_mm(model, z)) * 1e3
            assert abs(ezz) > 0.5 and chart[h] == pytest.approx(-ezz, abs=0.01)
    # a datum change, by contrast, moves the holes (the same formula, honestly computed)
    moved = apply_changes(model, [Change("installation.J.z_um", 5.0)])
    assert all(abs(abs(v) - 5.0) < 0.1 for v in expected_change_um(model, moved, holes).values())
