"""The engine's table of states and commands, its command registry and its seams
(message hooks, preprocessors), on the instant mock axes (issue 19)."""

from __future__ import annotations

import asyncio
import itertools

import pytest

from drivers.interfaces import CommunicationLost, DeviceTimeout
from drivers.testing import InstantMockLinearAxis, InstantMockRotaryAxis
from station.sequencer import messages as m
from station.sequencer.engine import COMMANDS, TRANSITIONS, Devices, Engine, EngineStateError, PlanEnded, State


def make_engine(**kw):
    z, c = InstantMockLinearAxis("Z"), InstantMockRotaryAxis("C")
    eng = Engine(Devices(z, c), retry_backoff_s=0.0, sleep=lambda s: asyncio.sleep(0), **kw)
    return eng, z, c


def plan(n=3):
    for i in range(n):
        yield m.Move("Z", float(i))
        yield m.Checkpoint(f"p{i}")
    return "done"


def test_the_tables_cover_every_state_and_every_command_names_reachable_states():
    assert set(TRANSITIONS) == set(State)
    for state, targets in TRANSITIONS.items():
        assert targets <= set(State), state
        # a fault or an e-stop can happen anywhere
        assert {State.FAULTED, State.ESTOPPED} <= targets | {state}, state
    assert set(COMMANDS) == {"home", "run", "pause", "resume", "stop", "abort", "reset"}
    for rule in COMMANDS.values():
        assert rule.states and rule.otherwise


@pytest.mark.parametrize("state,command", list(itertools.product(list(State), ["pause", "resume", "stop", "abort",
                                                                                 "reset", "home"])))
def test_a_command_in_a_state_that_does_not_take_it_is_refused_by_name_never_ignored(state, command):
    async def go():
        eng, z, c = make_engine()
        eng.state = state  # the table is what is tested here, not how the state was reached
        allowed = eng.allowed(command)
        try:
            fn = getattr(eng, command)
            out = fn()
            if asyncio.iscoroutine(out):
                await out
            raised = None
        except EngineStateError as exc:
            raised = str(exc)
        except PlanEnded:  # reset may fault on the drives: the state did accept it
            raised = None
        return allowed, raised

    allowed, raised = asyncio.run(go())
    assert allowed == (state in COMMANDS[command].states)
    if allowed:
        assert raised is None
    else:
        assert raised == f"cannot {command} while {state.value}: {COMMANDS[command].otherwise}"


def test_an_illegal_state_change_is_a_bug_refused_by_the_engine():
    eng, z, c = make_engine()
    with pytest.raises(EngineStateError, match="illegal state change idle -> running"):
        eng._set(State.RUNNING)
    assert eng.state == State.IDLE


def test_homing_runs_as_messages_that_hooks_see():
    seen = []

    async def go():
        eng, z, c = make_engine()
        eng.add_msg_hook(lambda msg: seen.append(msg))
        await eng.home()
        return eng.state, z.count("home"), c.count("home")

    state, zh, ch = asyncio.run(go())
    assert state == State.READY and zh == ch == 1
    assert seen == [m.Enable("Z"), m.Home("Z"), m.Enable("C"), m.Home("C"), m.Wait(("Z", "C"))]


def test_a_hook_that_raises_fails_the_step_as_a_device_would_and_can_be_removed():
    async def go():
        eng, z, c = make_engine()
        await eng.home()

        async def lose_the_link(msg):
            if isinstance(msg, m.Move) and msg.position == 1.0:
                raise CommunicationLost("link lost (injected at the second move)", "Z")

        remove = eng.add_msg_hook(lose_the_link)
        with pytest.raises(PlanEnded) as ended:
            await eng.run(plan())
        state, stops = eng.state, z.count("stop")
        remove()
        await eng.reset()
        await eng.home()
        return ended.value, state, stops, await eng.run(plan())

    ended, state, stops, out = asyncio.run(go())
    assert ended.outcome == "faulted" and "injected at the second move" in ended.reason
    assert state == State.FAULTED and stops >= 1 and out == "done"


def test_preprocessors_wrap_every_plan():
    def count_moves(inner):
        n = 0
        answer = None
        while True:
            try:
                msg = inner.send(answer)
            except StopIteration as done:
                return (done.value, n)
            n += isinstance(msg, m.Move)
            answer = yield msg

    async def go():
        eng, z, c = make_engine()
        eng.preprocessors.append(count_moves)
        await eng.home()
        return await eng.run(plan(4))

    assert asyncio.run(go()) == ("done", 4)


def test_a_registered_command_carries_out_its_message_and_the_old_one_comes_back():
    got = []

    async def go():
        eng, z, c = make_engine()
        await eng.home()

        def emitting():
            yield m.Emit("frame", 1)
            yield m.Emit("frame", 2)
            return "ok"

        async def keep(engine, msg):
            got.append((engine is eng, msg.body))

        restore = eng.register_command(m.Emit, keep)
        first = await eng.run(emitting())
        restore()
        events = []
        eng.subscribe(lambda ev: events.append(ev.kind))
        second = await eng.run(emitting())
        return first, second, events

    first, second, events = asyncio.run(go())
    assert first == second == "ok" and got == [(True, 1), (True, 2)]
    assert events.count("document") == 2  # the default: an event, nothing more


def test_a_message_that_is_not_retryable_is_not_retried():
    @__import__("dataclasses").dataclass(frozen=True)
    class ReadOnce(m.ReadAxis):
        retryable = False

    async def go():
        eng, z, c = make_engine()
        await eng.home()

        def reads(msg):
            yield msg
            return "read"

        z.fail("read_position", DeviceTimeout, times=1)
        retried = await eng.run(reads(m.ReadAxis("Z")))
        n_retries = eng.retries_used
        z.fail("read_position", DeviceTimeout, times=1)
        with pytest.raises(PlanEnded) as ended:
            await eng.run(reads(ReadOnce("Z")))
        return retried, n_retries, ended.value, eng.retries_used

    retried, n_retries, ended, after = asyncio.run(go())
    assert retried == "read" and n_retries == 1
    assert ended.outcome == "faulted" and "DeviceTimeout" in ended.reason and after == 0


def test_a_plan_message_without_a_command_faults_the_engine():
    @__import__("dataclasses").dataclass(frozen=True)
    class Unknown:
        retryable = True

    async def go():
        eng, z, c = make_engine()
        await eng.home()

        def odd():
            yield Unknown()

        with pytest.raises(PlanEnded) as ended:
            await eng.run(odd())
        return ended.value, eng.state

    ended, state = asyncio.run(go())
    assert ended.outcome == "faulted" and "no command for message" in ended.reason and state == State.FAULTED


def test_report_fault_and_note_are_the_public_way_in():
    async def go():
        eng, z, c = make_engine()
        await eng.home()
        events = []
        eng.subscribe(lambda ev: events.append((ev.kind, ev.text)))
        eng.note("axes checked before the run")
        await eng.report_fault(DeviceTimeout("no answer to the status read", "C"))
        return eng.state, eng.reason, events, z.count("stop"), c.count("stop")

    state, reason, events, zs, cs = asyncio.run(go())
    assert state == State.FAULTED and "no answer to the status read" in reason
    assert events[0] == ("note", "axes checked before the run") and ("fault", reason) in events
    assert zs == cs == 1  # the axes stopped
