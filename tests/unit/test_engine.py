"""The run engine's state machine, on in-memory axes (``drivers.testing``'s instant
mock axes; the end-to-end tests use the twins)."""

from __future__ import annotations

import asyncio

import pytest

from drivers.interfaces import DeviceTimeout, DriveFault
from drivers.testing import InstantMockLinearAxis, InstantMockRotaryAxis
from station.sequencer import messages as m
from station.sequencer.engine import Devices, Engine, EngineStateError, PlanEnded, State


def make_engine():
    z, c = InstantMockLinearAxis("Z"), InstantMockRotaryAxis("C")
    eng = Engine(Devices(z, c), retry_backoff_s=0.0, sleep=lambda s: asyncio.sleep(0))
    states = []
    eng.subscribe(lambda ev: states.append(ev.state) if ev.kind == "state" else None)
    return eng, z, c, states


def scan_plan(n=5, log=None):
    for i in range(n):
        yield m.Move("Z", 10.0 * i)
        yield m.Checkpoint(f"point {i}")
        pos = yield m.ReadAxis("Z")
        if log is not None:
            log.append(pos)
        yield m.Progress(i + 1, n)
    return "done"


def test_plan_runs_and_returns_its_value():
    async def go():
        eng, z, c, states = make_engine()
        with pytest.raises(EngineStateError, match="home first"):
            await eng.run(scan_plan())
        await eng.home()
        log = []
        out = await eng.run(scan_plan(4, log))
        return eng, out, log, states

    eng, out, log, states = asyncio.run(go())
    assert out == "done" and log == [0.0, 10.0, 20.0, 30.0]
    assert eng.state == State.READY and eng.progress[:2] == (4, 4)
    assert states[:3] == [State.HOMING, State.READY, State.RUNNING]


def test_the_surface_device_is_given_the_camera_blur_the_plan_names():
    """``MeasureSurface.blur_px`` reaches the station's defect detection as its keyword
    (the camera's blur from the bore scan's holes), None when the plan names none; and
    ``hole_places`` (where the part's holes show) when the plan gives them, else the
    device is called as before (a detection that takes no places still serves)."""
    calls = []

    def surface(image, blur_px=None):
        calls.append((image, blur_px))
        return [image]

    def placed(image, blur_px=None, hole_places=None):
        calls.append((image, blur_px, hole_places))
        return [image]

    def plan():
        a = yield m.MeasureSurface("frame a", blur_px=1.21)
        b = yield m.MeasureSurface("frame b")
        return a + b

    def plan_with_places():
        a = yield m.MeasureSurface("frame c", blur_px=1.3, hole_places=((5.0, 6.0, 40.0),))
        b = yield m.MeasureSurface("frame d", hole_places=())
        return a + b

    async def go(device, p):
        z, c = InstantMockLinearAxis("Z"), InstantMockRotaryAxis("C")
        eng = Engine(Devices(z, c, surface=device), retry_backoff_s=0.0, sleep=lambda s: asyncio.sleep(0))
        await eng.home()
        return await eng.run(p)

    assert asyncio.run(go(surface, plan())) == ["frame a", "frame b"]
    assert calls == [("frame a", 1.21), ("frame b", None)]
    calls.clear()
    assert asyncio.run(go(placed, plan_with_places())) == ["frame c", "frame d"]
    assert calls == [("frame c", 1.3, ((5.0, 6.0, 40.0),)), ("frame d", None, ())]


def test_pause_takes_effect_at_a_checkpoint_and_resume_continues():
    async def go():
        eng, z, c, states = make_engine()
        await eng.home()
        log = []
        z.hold()
        task = asyncio.create_task(eng.run(scan_plan(3, log)))
        await asyncio.sleep(0.01)
        eng.pause()  # requested while the first move is under way
        assert eng.state == State.RUNNING
        z.release()
        for _ in range(100):
            await asyncio.sleep(0.001)
            if eng.state == State.PAUSED:
                break
        paused_state, logged_while_paused = eng.state, list(log)
        eng.resume()
        out = await task
        return paused_state, logged_while_paused, out, log

    paused_state, logged_while_paused, out, log = asyncio.run(go())
    assert paused_state == State.PAUSED
    assert logged_while_paused == []  # paused at the first checkpoint, before its read
    assert out == "done" and log == [0.0, 10.0, 20.0]


def test_abort_stops_axes_and_ends_aborted():
    async def go():
        eng, z, c, states = make_engine()
        await eng.home()
        z.hold()  # the move never finishes by itself
        task = asyncio.create_task(eng.run(scan_plan()))
        await asyncio.sleep(0.01)
        eng.abort("operator pressed abort")
        with pytest.raises(PlanEnded) as exc:
            await task
        return eng, z, c, exc.value

    eng, z, c, ended = asyncio.run(go())
    assert ended.outcome == "aborted" and "operator" in ended.reason
    assert z.count("stop") == 1 and c.count("stop") == 1
    assert eng.state == State.READY


def test_controlled_stop_ends_at_next_checkpoint():
    async def go():
        eng, z, c, _ = make_engine()
        await eng.home()
        log = []
        z.hold()
        task = asyncio.create_task(eng.run(scan_plan(5, log)))
        await asyncio.sleep(0.01)
        eng.stop()
        z.release()
        with pytest.raises(PlanEnded) as exc:
            await task
        return eng, exc.value, log

    eng, ended, log = asyncio.run(go())
    assert ended.outcome == "stopped" and log == []
    assert eng.state == State.READY


def test_transient_errors_are_retried_within_budget():
    async def go():
        eng, z, c, _ = make_engine()
        await eng.home()
        z.fail("move_to", DeviceTimeout("no reply", "Z"), times=2)
        out = await eng.run(scan_plan(2))
        return eng, out

    eng, out = asyncio.run(go())
    assert out == "done" and eng.retries_used == 2


def test_budget_exhausted_or_drive_fault_faults_the_engine_and_reset_recovers():
    async def go():
        eng, z, c, _ = make_engine()
        await eng.home()
        z.fail("move_to", DeviceTimeout("no reply", "Z"), times=4)
        with pytest.raises(PlanEnded) as e1:
            await eng.run(scan_plan(2))
        s1, stops1 = eng.state, z.count("stop")
        with pytest.raises(EngineStateError):
            await eng.run(scan_plan(2))
        await eng.reset()
        await eng.home()
        z.fail("move_to", DriveFault(0x20, "overcurrent", "Z"))
        with pytest.raises(PlanEnded) as e2:
            await eng.run(scan_plan(2))
        s2, retries = eng.state, eng.retries_used
        await eng.reset()
        await eng.home()
        out = await eng.run(scan_plan(2))
        return e1.value, s1, stops1, e2.value, s2, retries, out

    e1, s1, stops1, e2, s2, retries, out = asyncio.run(go())
    assert e1.outcome == "faulted" and "DeviceTimeout" in e1.reason and s1 == State.FAULTED and stops1 == 1
    assert e2.outcome == "faulted" and "overcurrent" in e2.reason and s2 == State.FAULTED
    assert retries == 0  # a drive fault is not retried
    assert out == "done"


def test_estop_code_puts_engine_in_estopped():
    async def go():
        eng, z, c, _ = make_engine()
        await eng.home()
        z.fail("move_to", DriveFault(0x12, "emergency stop", "Z"))
        with pytest.raises(PlanEnded):
            await eng.run(scan_plan(1))
        return eng.state

    assert asyncio.run(go()) == State.ESTOPPED


def test_a_plan_that_raises_between_messages_faults_the_engine_instead_of_leaving_it_running():
    def broken():
        yield m.Move("Z", 5.0)
        raise RuntimeError("compensation did not converge")

    async def go():
        eng, z, c, _ = make_engine()
        await eng.home()
        with pytest.raises(PlanEnded) as e:
            await eng.run(broken())
        state, stops = eng.state, z.count("stop")
        await eng.reset()
        await eng.home()
        return e.value, state, stops, await eng.run(scan_plan(2))

    ended, state, stops, out = asyncio.run(go())
    assert ended.outcome == "faulted" and "did not converge" in ended.reason
    assert state == State.FAULTED and stops == 1 and out == "done"


def test_a_table_wound_up_by_many_parts_is_a_problem_to_re_reference_before_the_next():
    from station.sequencer.engine import C_WIND_LIMIT_DEG

    async def go():
        eng, z, c, _ = make_engine()
        await eng.home()
        c.position = C_WIND_LIMIT_DEG - 1.0
        ok = await eng.axes_problem()
        c.position = C_WIND_LIMIT_DEG + 360.0
        return ok, await eng.axes_problem()

    ok, wound = asyncio.run(go())
    assert ok is None and wound == "C has wound 101 turns"


def test_a_fault_latched_while_ready_is_an_axes_problem_and_reset_leaves_the_axis_disabled():
    async def go():
        eng, z, c, _ = make_engine()
        await eng.home()
        ok = await eng.axes_problem()
        z.trip(0x20, "motor overcurrent")  # the drive faults while nothing runs
        tripped = await eng.axes_problem()
        await z.reset_fault()  # acknowledged, but a drive comes back disabled
        reset = await eng.axes_problem()
        return ok, tripped, reset

    ok, tripped, reset = asyncio.run(go())
    assert ok is None and tripped == "Z reports fault 0x0020" and reset == "Z is not enabled"


def test_a_watchdog_fault_is_a_link_fault_until_reset_and_no_other_fault_is():
    from station.sequencer.engine import link_fault

    async def go():
        eng, z, c, _ = make_engine()
        await eng.home()
        seen = []
        # a drive fault is not retried (one failure); a timeout is, until the budget ends
        for fault, times in ((DriveFault(0x11, "communication watchdog expired", "Z"), 1),
                             (DriveFault(0x20, "overcurrent", "Z"), 1), (DeviceTimeout("no reply", "Z"), 4)):
            z.fail("move_to", fault, times=times)
            with pytest.raises(PlanEnded):
                await eng.run(scan_plan(2))
            seen.append((eng.state, link_fault(eng)))
            await eng.reset()
            seen.append((eng.state, link_fault(eng)))
            await eng.home()
        return seen

    seen = asyncio.run(go())
    assert seen == [(State.FAULTED, True), (State.IDLE, False),
                    (State.FAULTED, False), (State.IDLE, False),
                    (State.FAULTED, False), (State.IDLE, False)]


def test_an_abort_whose_cancellation_a_step_swallowed_still_ends_the_plan_at_the_next_step():
    """asyncio.wait_for before Python 3.12 returns the result of a future that completed
    as its task was cancelled: the abort's cancellation is then lost inside the step. The
    abort request itself must still end the plan, before the next step."""

    async def go():
        eng, z, c, _ = make_engine()
        await eng.home()
        inside = asyncio.Event()

        async def swallowing_step(msg):
            if isinstance(msg, m.Checkpoint) and msg.label == "point 1":
                inside.set()
                try:
                    await asyncio.sleep(1.0)
                except asyncio.CancelledError:
                    pass  # the step's result came back as the task was cancelled

        eng.add_msg_hook(swallowing_step)
        log = []
        task = asyncio.create_task(eng.run(scan_plan(5, log)))
        await inside.wait()
        eng.abort("operator pressed abort")
        with pytest.raises(PlanEnded) as exc:
            await task
        return eng, exc.value, log, z

    eng, ended, log, z = asyncio.run(go())
    assert ended.outcome == "aborted" and "operator" in ended.reason
    assert log == [0.0]  # point 1's read and everything after it never ran
    assert z.count("stop") == 1 and eng.state == State.READY
