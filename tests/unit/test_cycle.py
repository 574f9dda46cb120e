"""Cycle time: the minimum-time move, the ledger's replay at real speed, the lower
bound of a plan, the plan's concurrent approach and the engine's ledger.

Hand facts: a trapezoid's duration from v and a (a triangle below v^2/a), a
unidirectional approach from above as two rest-to-rest moves, a replay whose wait
covers the rest of its axis' profile plus the measured overhead beyond the scaled
motion, frames at the sensor's time."""

from __future__ import annotations

import asyncio
import math

import pytest

from drivers.interfaces import CameraTiming
from station.inspection.scan import ScanSettings, approach
from station.motion import AxisLimits, approach_time_s, move_time_s
from station.sequencer import messages as m
from station.sequencer.cycle import Step, frame_poses, lower_bound, machine_time
from station.sequencer.engine import Devices, Engine, Timeouts

from drivers.testing import InstantMockLinearAxis, InstantMockRotaryAxis

Z = AxisLimits(velocity=50.0, acceleration=500.0)
C = AxisLimits(velocity=90.0, acceleration=720.0)
CAM = CameraTiming(exposure_s=0.008, readout_s=0.025)


def test_minimum_time_move_is_the_trapezoid_and_the_triangle_when_short():
    # 100 mm: 0.1 s ramps cover 2 x 2.5 mm, 95 mm cruise at 50 mm/s -> 0.2 + 1.9
    assert move_time_s(100.0, Z) == pytest.approx(2.1, abs=1e-12)
    # 1 mm < v^2/a = 5 mm: a triangle, 2 sqrt(d/a)
    assert move_time_s(1.0, Z) == pytest.approx(2 * math.sqrt(1.0 / 500.0), abs=1e-12)
    assert move_time_s(-1.0, Z) == move_time_s(1.0, Z)
    assert move_time_s(0.0, Z) == 0.0


def test_unidirectional_approach_from_above_goes_past_and_back():
    up = approach_time_s(10.0, 30.0, Z, 0.5)
    assert up == pytest.approx(move_time_s(20.0, Z))
    down = approach_time_s(30.0, 10.0, Z, 0.5)
    assert down == pytest.approx(move_time_s(20.5, Z) + move_time_s(0.5, Z))
    assert down > up


def test_limits_refuse_nonsense():
    for v, a in ((0.0, 1.0), (1.0, -1.0), (math.nan, 1.0)):
        with pytest.raises(ValueError):
            AxisLimits(v, a)
    with pytest.raises(ValueError):
        CameraTiming(-0.001, 0.02)


def ledger_two_poses():
    """Z from 0 up to 70 (C from 0 up to 50 at once), 3 frames; then C back down to 10
    with an approach, 1 frame. Wall times as a 1e5 time scale leaves them."""
    return [
        Step("move", 0.002, axis="Z", start=0.0, target=70.0, velocity=50.0, acceleration=500.0),
        Step("move", 0.002, axis="C", start=0.0, target=50.0, velocity=90.0, acceleration=720.0),
        Step("wait", 0.001, axis="C"),
        Step("wait", 0.001, axis="Z"),
        Step("settle", 0.0501, seconds=0.05),
        Step("frame", 0.120), Step("vision", 0.009), Step("frame", 0.118), Step("vision", 0.008),
        Step("frame", 0.119), Step("vision", 0.010),
        Step("move", 0.002, axis="C", start=50.0, target=9.5, velocity=90.0, acceleration=720.0),
        Step("wait", 0.001, axis="C"),
        Step("move", 0.002, axis="C", start=9.5, target=10.0, velocity=90.0, acceleration=720.0),
        Step("wait", 0.001, axis="C"),
        Step("settle", 0.0502, seconds=0.05),
        Step("frame", 0.121), Step("vision", 0.009),
        Step("plan", 0.003), Step("read", 0.002),
    ]


def test_measured_machine_time_is_the_sum_of_the_walls():
    steps = ledger_two_poses()
    t = machine_time(steps)
    assert t.basis == "measured"
    assert t.total_s == pytest.approx(sum(s.wall_s for s in steps))
    assert t.breakdown["frames_s"] == pytest.approx(0.120 + 0.118 + 0.119 + 0.121)


def test_replay_at_real_speed_by_hand():
    steps = ledger_two_poses()
    ts, poll = 1e5, 0.02
    got = machine_time(steps, time_scale=ts, camera=CAM, poll_s={"Z": poll, "C": poll})
    assert got.basis == "modelled"
    late = 0.5 * poll * (1 - 1 / ts)
    tz, tc = move_time_s(70.0, Z), move_time_s(50.0, C)
    # both moves sent (2 ms each); C waited for: the rest of its profile, seen half a
    # poll late, and the wait's wall beyond the scaled motion (tc / ts of its 1 ms)
    t = 0.004
    t += tc + late + (0.001 - tc / ts)
    rest_z = 0.002 + tz - t  # Z started at 2 ms and runs longer
    assert rest_z > 0
    t += rest_z + late + (0.001 - rest_z / ts)
    for leg in (move_time_s(40.5, C), move_time_s(0.5, C)):
        t += 0.002 + leg + late + (0.001 - leg / ts)
    moves = t
    assert got.breakdown["moves_s"] == pytest.approx(moves, rel=1e-12)
    assert got.breakdown["frames_s"] == pytest.approx(4 * CAM.frame_s)
    assert got.breakdown["settle_s"] == pytest.approx(0.10)
    assert got.breakdown["vision_s"] == pytest.approx(0.036)
    assert got.breakdown["other_s"] == pytest.approx(0.005)
    assert got.total_s == pytest.approx(sum(got.breakdown.values()))
    # at time scale 1 the walls are the machine's: a wait is its wall when that covers the motion
    real = [Step("move", 0.002, axis="Z", start=0.0, target=70.0, velocity=50.0, acceleration=500.0),
            Step("wait", tz + 0.013, axis="Z")]
    assert machine_time(real, time_scale=1.0, poll_s={"Z": poll}).total_s == pytest.approx(0.002 + tz + 0.013)


def test_frame_poses_group_frames_by_pose():
    start, poses = frame_poses(ledger_two_poses())
    assert start == {"Z": 0.0, "C": 0.0}
    assert poses == [({"Z": 70.0, "C": 50.0}, 3), ({"Z": 70.0, "C": 10.0}, 1)]


def test_lower_bound_by_hand():
    b = lower_bound(ledger_two_poses(), limits={"Z": Z, "C": C}, approach={"Z": 0.5, "C": 0.5},
                    settle_s=0.05, camera=CAM)
    first = max(move_time_s(70.0, Z), move_time_s(50.0, C))
    second = move_time_s(40.5, C) + move_time_s(0.5, C)
    assert b.breakdown["moves_s"] == pytest.approx(first + second)
    assert b.breakdown["settle_s"] == pytest.approx(0.10)
    # three frames in a row: exposure + 2 readout-limited periods; one frame: its exposure
    assert b.breakdown["frames_s"] == pytest.approx(0.008 + 2 * 0.025 + 0.008)
    assert b.breakdown["vision_s"] == 0.0
    assert b.total_s < machine_time(ledger_two_poses(), time_scale=1e5, camera=CAM).total_s


def drive(plan, answers=None):
    """The messages a plan yields, fed None (or ``answers``)."""
    out = []
    result = None
    while True:
        try:
            msg = plan.send(result)
        except StopIteration as done:
            return out, done.value
        out.append(msg)
        result = None


def test_approach_straight_up_past_and_back_down_both_axes_at_once():
    at = {"Z": 10.0, "C": 100.0}
    msgs, moved = drive(approach({"C": 50.0, "Z": 20.0}, ScanSettings(), {"Z": Z, "C": C}, at))
    assert moved
    assert msgs[0] == m.Move("C", 49.5, wait=False, velocity=90.0, acceleration=720.0)
    assert msgs[1] == m.Move("Z", 20.0, wait=False, velocity=50.0, acceleration=500.0)
    assert msgs[2:] == [m.Wait(("C",)), m.Move("C", 50.0, wait=False, velocity=90.0, acceleration=720.0),
                        m.Wait(("C", "Z"))]
    assert at == {"Z": 20.0, "C": 50.0}


def test_approach_does_nothing_where_the_axes_are_and_always_approaches_from_the_unknown():
    at = {"Z": 20.0, "C": 50.0}
    msgs, moved = drive(approach({"C": 50.0, "Z": 20.0 + 1e-9}, ScanSettings(), {}, at))
    assert (msgs, moved) == ([], False)
    msgs, moved = drive(approach({"C": 50.0, "Z": 20.0}, ScanSettings(), {}, {}))
    assert moved
    assert [x for x in msgs if isinstance(x, m.Move)] == [
        m.Move("C", 49.5, wait=False), m.Move("Z", 19.5, wait=False), m.Move("C", 50.0, wait=False),
        m.Move("Z", 20.0, wait=False)]


def test_approach_sends_the_second_legs_in_the_order_the_first_legs_end():
    # Z has far to go down, C a little: C's second leg first
    at = {"Z": 100.0, "C": 50.0}
    msgs, _ = drive(approach({"C": 49.0, "Z": 10.0}, ScanSettings(), {"Z": Z, "C": C}, at))
    waits = [x.axes for x in msgs if isinstance(x, m.Wait)]
    assert waits == [("C",), ("Z",), ("C", "Z")]


def started_and_done(journal):
    """"Z start" when each move was sent, "Z done" when its wait ended, in time order."""
    events = [(c.started, f"{c.axis} start") for c in journal if c.method == "move_to"]
    events += [(math.inf if c.ended is None else c.ended, f"{c.axis} done")
               for c in journal if c.method == "wait_in_position"]
    return [name for _, name in sorted(events)]


def test_engine_runs_two_moves_at_once_and_keeps_a_ledger():
    async def main():
        journal = []  # both axes' calls, interleaved; moves take 0.2 s
        z = InstantMockLinearAxis("Z", delay_s=0.2, journal=journal, default_velocity=50.0, default_acceleration=500.0)
        c = InstantMockRotaryAxis("C", delay_s=0.2, journal=journal)
        eng = Engine(Devices(z, c), retry_backoff_s=0.0)
        await eng.home()
        def plan():
            yield m.Move("Z", 40.0, wait=False)
            yield m.Move("C", 30.0, wait=False, velocity=90.0, acceleration=720.0)
            yield m.Wait(("Z", "C"))
            yield m.Settle(0.0)
            return "ok"

        journal.clear()
        assert await eng.run(plan()) == "ok"
        return started_and_done(journal), eng, z, c

    events, eng, z, c = asyncio.run(main())
    # together: both started before either is waited for
    assert events == ["Z start", "C start", "Z done", "C done"]
    moves = [s for s in eng.ledger.steps if s.kind == "move"]
    assert [(s.axis, s.start, s.target, s.velocity, s.acceleration) for s in moves] == [
        ("Z", 0.0, 40.0, 50.0, 500.0), ("C", 0.0, 30.0, 90.0, 720.0)]
    assert [s.axis for s in eng.ledger.steps if s.kind == "wait"] == ["Z", "C"]
    assert c.calls_to("move_to")[0].args[1:] == (90.0, 720.0)
    # Z's timeout from its profile: twice 40 mm at 50 mm/s, 500 mm/s^2, plus the margin
    z_timeout, c_timeout = (ax.calls_to("wait_in_position")[-1].args[0] for ax in (z, c))
    assert z_timeout == pytest.approx(2 * move_time_s(40.0, Z) + Timeouts().move_margin_s)
    assert c_timeout == pytest.approx(2 * move_time_s(30.0, C) + Timeouts().move_margin_s)


def test_move_timeout_from_the_profile_capped_and_the_fallback_when_the_speed_is_unknown():
    t = Timeouts(move_s=60.0, move_margin_s=5.0)
    assert t.for_move(100.0, 50.0, 500.0) == pytest.approx(2 * 2.1 + 5.0)
    assert t.for_move(100.0, 0.01, 500.0) == 60.0  # 10,000 s at that speed: capped
    assert t.for_move(None, 50.0, 500.0) == 60.0
    assert t.for_move(100.0, None, None) == 60.0
