"""The run engine: one state machine that carries out plans on the station's devices.

States (``State``) and the legal changes between them are one declarative table,
``TRANSITIONS`` (in the manner of Bluesky's ``RunEngineStateMachine``); which operator
command each state accepts is another, ``COMMANDS``. The engine checks both; the API
asks the engine (``Engine.check``/``Engine.allowed``) instead of copying the rules.

    idle --home--> homing --> ready --run--> running --> ready (plan done)
    running --pause--> (at the next checkpoint) paused --resume--> running
    running/paused --stop--> stopping (at the next checkpoint) --> ready, plan ends "stopped"
    running/paused --abort--> aborting (axes stopped at once) --> ready, plan ends "aborted"
    any --driver fault--> faulted (axes stopped, reason kept) --reset--> idle
    any --e-stop seen--> estopped --reset (after release)--> idle

Messages are carried out through a command registry (``register_command``, as
Bluesky's), so a new kind of step is one function, not another branch. The seams for
instrumentation and fault injection are public: ``msg_hooks`` (called before every
message, homing's included; a hook that raises fails that step as a device would)
and ``preprocessors`` (functions that wrap a plan before it runs).

Transient driver errors (timeout, lost link, garbled reply) are retried within a
budget for steps whose message is ``retryable``; a drive fault, a following error or
an exhausted budget faults the engine. Every move's timeout comes from its distance,
speed and acceleration (``Timeouts.for_move``). The engine, not the plan, talks to
drivers.
"""

from __future__ import annotations

import asyncio
import enum
import inspect as _inspect
import time
from dataclasses import dataclass, field
from typing import Any, Awaitable, Callable, Generator

from drivers.interfaces import (
    Camera,
    CommunicationLost,
    DeviceTimeout,
    DriveFault,
    DriverError,
    LinearAxis,
    MoveInterrupted,
    PositionEncoder,
    ProtocolError,
    RotaryAxis,
)
from drivers.interfaces.register_map import FaultCode
from station.motion import AxisLimits, move_time_s
from station.sequencer import messages as m
from station.sequencer.cycle import CycleLedger, Step
from station.sequencer.frames import FrameCheck


class State(str, enum.Enum):
    IDLE = "idle"
    HOMING = "homing"
    READY = "ready"
    RUNNING = "running"
    PAUSED = "paused"
    STOPPING = "stopping"
    ABORTING = "aborting"
    FAULTED = "faulted"
    ESTOPPED = "estopped"


#: the legal state changes, from -> {to}; anything else is a bug in the engine and is
#: refused (``_set``), never carried out silently
TRANSITIONS: dict[State, frozenset[State]] = {
    State.IDLE: frozenset({State.HOMING, State.IDLE, State.FAULTED, State.ESTOPPED}),
    State.HOMING: frozenset({State.READY, State.FAULTED, State.ESTOPPED}),
    State.READY: frozenset({State.RUNNING, State.HOMING, State.IDLE, State.READY, State.FAULTED, State.ESTOPPED}),
    State.RUNNING: frozenset({State.PAUSED, State.STOPPING, State.ABORTING, State.READY, State.FAULTED,
                              State.ESTOPPED}),
    State.PAUSED: frozenset({State.RUNNING, State.STOPPING, State.ABORTING, State.FAULTED, State.ESTOPPED}),
    State.STOPPING: frozenset({State.READY, State.ABORTING, State.FAULTED, State.ESTOPPED}),
    State.ABORTING: frozenset({State.READY, State.FAULTED, State.ESTOPPED}),
    State.FAULTED: frozenset({State.IDLE, State.FAULTED, State.ESTOPPED}),
    State.ESTOPPED: frozenset({State.IDLE, State.FAULTED, State.ESTOPPED}),
}


@dataclass(frozen=True)
class CommandRule:
    """The states in which an operator's command is accepted, and what to tell the
    operator otherwise."""

    states: frozenset[State]
    otherwise: str


_ACTIVE = frozenset({State.RUNNING, State.PAUSED, State.STOPPING})

#: command -> the states that accept it. A command accepted where it has nothing left to
#: do (pause while paused, stop while stopping) is accepted and changes nothing.
COMMANDS: dict[str, CommandRule] = {
    "home": CommandRule(frozenset({State.IDLE, State.READY}), "reset first"),
    "run": CommandRule(frozenset({State.READY}), "home first"),
    "pause": CommandRule(_ACTIVE, "nothing is running"),
    "resume": CommandRule(frozenset({State.PAUSED, State.RUNNING}), "nothing is paused"),
    "stop": CommandRule(_ACTIVE, "nothing is running"),
    "abort": CommandRule(_ACTIVE, "nothing is running"),
    "reset": CommandRule(frozenset({State.FAULTED, State.ESTOPPED, State.IDLE, State.READY}),
                         "stop or abort the plan first"),
}


class PlanEnded(Exception):
    """A plan did not complete: ``outcome`` is "stopped", "aborted" or "faulted"."""

    def __init__(self, outcome: str, reason: str):
        super().__init__(f"{outcome}: {reason}")
        self.outcome = outcome
        self.reason = reason


class EngineStateError(RuntimeError):
    """A command that the present state does not allow (e.g. run while faulted)."""


#: errors worth repeating an idempotent step for: the link, not the machine
TRANSIENT = (DeviceTimeout, CommunicationLost, ProtocolError)


@dataclass
class Devices:
    z: LinearAxis
    c: RotaryAxis
    encoder: PositionEncoder | None = None
    camera: Camera | None = None
    #: image -> list of hole measurements (the vision stage), run off the event loop
    measure: Callable[[Any], Any] | None = None
    #: (image, blur_px=camera blur px or None[, hole_places=the part's holes in the frame,
    #: (x, y, reach) px each]) -> list of surface defects (the vision
    #: stage's defect detection), off the loop
    surface: Callable[..., Any] | None = None

    def axis(self, name: str):
        if name == "Z":
            return self.z
        if name == "C":
            return self.c
        raise ValueError(f"unknown axis {name!r}")


#: a rotary table wound this far is re-referenced before the next inspection (its drive's
#: 32-bit count holds about 596 turns at 0.0001 deg per count; homing to the nearest of
#: its once-per-turn marks costs at most half a turn)
C_WIND_LIMIT_DEG = 100 * 360.0


@dataclass
class Timeouts:
    #: a move whose profile is known gets twice its trapezoid plus ``move_margin_s``
    #: (a loaded link, a drive's settling), never more than ``move_s``; ``move_s``
    #: alone when the speed is not known (the longest move of the stroke at the
    #: slowest speed, with margin)
    move_s: float = 60.0
    move_margin_s: float = 5.0
    home_s: float = 120.0

    def for_move(self, distance: float | None, velocity: float | None, acceleration: float | None) -> float:
        if distance is None or not velocity or not acceleration or velocity <= 0 or acceleration <= 0:
            return self.move_s
        return min(self.move_s, 2.0 * move_time_s(distance, AxisLimits(velocity, acceleration)) + self.move_margin_s)


@dataclass
class EngineEvent:
    time: float
    kind: str  # "state", "progress", "note", "retry", "fault"
    state: State
    text: str = ""
    data: dict = field(default_factory=dict)


#: a message's command: carries the message out on the engine's devices, returns the
#: value sent back into the plan
Command = Callable[["Engine", m.Msg], Awaitable[Any]]
#: called before a message's command; may be a coroutine function; raising fails the step
MsgHook = Callable[[m.Msg], Any]
#: wraps a plan (a generator of messages) before it runs
Preprocessor = Callable[[Generator[m.Msg, Any, Any]], Generator[m.Msg, Any, Any]]


class Engine:
    def __init__(self, devices: Devices, *, retries: int = 3, retry_backoff_s: float = 0.05,
                 timeouts: Timeouts | None = None, sleep: Callable[[float], Awaitable[None]] = asyncio.sleep):
        self.devices = devices
        self.retries = retries
        self.retry_backoff_s = retry_backoff_s
        self.timeouts = timeouts or Timeouts()
        self._sleep = sleep
        self.state = State.IDLE
        self.reason = ""
        #: the drive's fault code of the last fault (drivers.interfaces.register_map.FaultCode;
        #: None for a fault without one, and after a reset)
        self.fault_code: int | None = None
        self.progress: tuple[int, int, str] = (0, 0, "")
        self._listeners: list[Callable[[EngineEvent], None]] = []
        #: the seams (module docstring): hooks see every message before it runs,
        #: preprocessors wrap every plan
        self.msg_hooks: list[MsgHook] = []
        self.preprocessors: list[Preprocessor] = []
        self._commands: dict[type, Command] = dict(_DEFAULT_COMMANDS)
        self._resume = asyncio.Event()
        self._resume.set()
        self._stop_requested = False
        self._abort_requested: str | None = None
        self._pause_requested = False
        self._task: asyncio.Task | None = None
        self.retries_used = 0
        #: black and frozen frames are camera faults, not images to measure
        self.frame_check = FrameCheck()
        #: the steps of the last run with their wall times (station.sequencer.cycle)
        self.ledger = CycleLedger()
        #: per axis: where it was last sent in this run (None: read before its first move)
        self._at: dict[str, float] = {}
        #: per axis: the move (or homing) under way that a Wait collects, and its timeout
        self._pending: dict[str, tuple[m.Msg, float]] = {}

    # ------------------------------------------------------------------ the state machine
    def allowed(self, command: str) -> bool:
        """Whether the present state accepts ``command`` (``COMMANDS``)."""
        return self.state in COMMANDS[command].states

    def check(self, command: str) -> None:
        """Raise :class:`EngineStateError` unless the present state accepts ``command``."""
        rule = COMMANDS[command]
        if self.state not in rule.states:
            raise EngineStateError(f"cannot {command} while {self.state.value}: {rule.otherwise}")

    # ------------------------------------------------------------------ events
    def subscribe(self, fn: Callable[[EngineEvent], None]) -> Callable[[], None]:
        """Call ``fn`` with every event; returns a function that unsubscribes it."""
        self._listeners.append(fn)
        return lambda: self.unsubscribe(fn)

    def unsubscribe(self, fn: Callable[[EngineEvent], None]) -> None:
        """Stop calling ``fn``; a listener that is not subscribed is ignored."""
        try:
            self._listeners.remove(fn)
        except ValueError:
            pass

    def note(self, text: str, **data) -> None:
        """Record something worth the event log (a "note" event), from the plan's
        owner as a plan's ``Note`` message does."""
        self._emit("note", text, **data)

    async def report_fault(self, exc: BaseException) -> None:
        """A fault found outside a plan (a drive that faulted while nothing ran, a
        failed check before a run): the axes are stopped and the engine faults (or
        e-stops, by the fault's code) with the error as its reason."""
        await self._fault(exc)

    def _emit(self, kind: str, text: str = "", **data) -> None:
        ev = EngineEvent(time.time(), kind, self.state, text, data)
        for fn in list(self._listeners):
            try:
                fn(ev)
            except Exception:  # noqa: BLE001 - a broken listener must not stop the machine
                pass

    def _set(self, state: State, reason: str = "") -> None:
        if state not in TRANSITIONS[self.state]:
            raise EngineStateError(f"illegal state change {self.state.value} -> {state.value}")
        self.state = state
        if reason:
            self.reason = reason
        self._emit("state", reason)

    # ------------------------------------------------------------------ commands
    def register_command(self, msg_type: type, command: Command) -> Callable[[], None]:
        """Carry out messages of ``msg_type`` (and its subclasses without a command of
        their own) with ``command(engine, msg)``; returns a function that puts back the
        command it replaced."""
        previous = self._commands.get(msg_type)
        self._commands[msg_type] = command

        def restore() -> None:
            if previous is None:
                self._commands.pop(msg_type, None)
            else:
                self._commands[msg_type] = previous

        return restore

    def add_msg_hook(self, hook: MsgHook) -> Callable[[], None]:
        """Call ``hook(msg)`` before every message; returns a function that removes it."""
        self.msg_hooks.append(hook)

        def remove() -> None:
            if hook in self.msg_hooks:
                self.msg_hooks.remove(hook)

        return remove

    async def home(self) -> None:
        """Enable and home both axes; idle (or ready) -> homing -> ready. Homing is a
        plan of messages too, so hooks see it."""
        self.check("home")
        self._set(State.HOMING)
        self._pending = {}
        self._at = {}
        run_ledger, self.ledger = self.ledger, CycleLedger()  # homing is not the last run's time
        try:
            await self._drive(home_plan(), done_reason="homed")
        finally:
            self.ledger = run_ledger

    def pause(self) -> None:
        """Pause at the plan's next checkpoint."""
        self.check("pause")
        if self.state == State.RUNNING:
            self._pause_requested = True
            self._resume.clear()

    def resume(self) -> None:
        self.check("resume")
        self._pause_requested = False
        self._resume.set()

    def stop(self) -> None:
        """Controlled stop: the plan ends at its next checkpoint, the current move completes."""
        self.check("stop")
        if self.state in (State.RUNNING, State.PAUSED):
            self._stop_requested = True
            self._resume.set()

    def abort(self, reason: str = "aborted by operator") -> None:
        """Stop the axes now and end the plan as aborted."""
        self.check("abort")
        self._abort_requested = reason
        self._resume.set()
        if self._task is not None:
            self._task.cancel()

    async def reset(self) -> None:
        """Acknowledge a fault or a released e-stop: reset the drives, back to idle (home again)."""
        self.check("reset")
        for ax in (self.devices.z, self.devices.c):
            try:
                # a link that dropped with the fault reconnects here: retried like any step
                await self._with_retries(ax.reset_fault, f"reset {getattr(ax, 'name', 'axis')}")
            except DriverError as exc:
                self.fault_code = getattr(exc, "code", None)  # the reset's own failure, not the fault it met
                self._set(State.FAULTED, f"reset failed on {getattr(ax, 'name', 'axis')}: {exc}")
                raise PlanEnded("faulted", self.reason) from exc
        self.reason = ""
        self.fault_code = None
        self._set(State.IDLE, "reset")

    # ------------------------------------------------------------------ running plans
    async def run(self, plan: Generator[m.Msg, Any, Any]) -> Any:
        """Carry out ``plan``; returns its return value, or raises :class:`PlanEnded`."""
        self.check("run")
        for pre in self.preprocessors:
            plan = pre(plan)
        self._stop_requested = False
        self._abort_requested = None
        self._pause_requested = False
        self._resume.set()
        self.retries_used = 0
        self.ledger = CycleLedger()
        self._at = {}
        self._pending = {}
        self._set(State.RUNNING)
        self._task = asyncio.create_task(self._drive(plan, done_reason="plan complete", abortable=True))
        try:
            return await self._task
        except asyncio.CancelledError:
            if self._abort_requested is None:
                raise
            reason = self._abort_requested
            self._set(State.ABORTING, reason)
            await self._stop_axes()
            plan.close()
            self._set(State.READY, reason)
            raise PlanEnded("aborted", reason) from None
        finally:
            self._task = None

    async def _drive(self, plan, *, done_reason: str, abortable: bool = False) -> Any:
        result: Any = None
        while True:
            if abortable and self._abort_requested is not None:
                # an abort cancels the plan's task, and a cancellation can be lost: before
                # Python 3.12, asyncio.wait_for returns the result of a future that completed
                # as it was cancelled (a driver's request, a render). The request itself
                # then ends the plan here, before its next step
                raise asyncio.CancelledError(self._abort_requested)
            t0 = time.perf_counter()
            try:
                msg = plan.send(result)
            except StopIteration as done:
                self.ledger.add(Step("plan", time.perf_counter() - t0))
                self._set(State.READY, done_reason)
                return done.value
            except Exception as exc:  # noqa: BLE001 - the plan's own code raised between messages
                # (a compensation that does not converge, a bug): nobody drives the machine
                # any more, so it is a fault, not a run left "running"
                self.ledger.add(Step("plan", time.perf_counter() - t0))
                await self._fault(exc)
                raise PlanEnded("faulted", self.reason) from exc
            self.ledger.add(Step("plan", time.perf_counter() - t0))
            try:
                result = await self._execute(msg)
            except PlanEnded:
                plan.close()
                raise
            except DriverError as exc:
                plan.close()
                await self._fault(exc)
                raise PlanEnded("faulted", self.reason) from exc
            except asyncio.CancelledError:
                raise
            except Exception as exc:  # noqa: BLE001 - a bug in a plan or the vision stage
                # must not leave the machine "running" with nobody driving it: stop the
                # axes and fault, so that reset and home bring the station back
                plan.close()
                await self._fault(exc)
                raise PlanEnded("faulted", self.reason) from exc

    def _command_for(self, msg: m.Msg) -> Command:
        for cls in type(msg).__mro__:
            command = self._commands.get(cls)
            if command is not None:
                return command
        raise TypeError(f"no command for message {msg!r}")

    async def _execute(self, msg: m.Msg) -> Any:
        command = self._command_for(msg)
        for hook in list(self.msg_hooks):
            out = hook(msg)
            if _inspect.isawaitable(out):
                await out
        return await command(self, msg)

    # ------------------------------------------------------------------ the default commands
    async def _cmd_checkpoint(self, msg: m.Checkpoint) -> None:
        if self._pause_requested:
            self._set(State.PAUSED, msg.label)
            await self._resume.wait()
            if not self._stop_requested:
                self._set(State.RUNNING, "resumed")
        if self._stop_requested:
            self._set(State.STOPPING, "stop requested")
            await self._stop_axes()
            self._set(State.READY, "stopped by operator")
            raise PlanEnded("stopped", "stopped by operator")

    async def _cmd_progress(self, msg: m.Progress) -> None:
        self.progress = (msg.done, msg.total, msg.text)
        self._emit("progress", msg.text, done=msg.done, total=msg.total)

    async def _cmd_note(self, msg: m.Note) -> None:
        self._emit("note", msg.text)

    async def _cmd_settle(self, msg: m.Settle) -> None:
        t0 = time.perf_counter()
        await self._sleep(msg.seconds)
        self.ledger.add(Step("settle", time.perf_counter() - t0, seconds=msg.seconds))

    async def _cmd_move(self, msg: m.Move) -> None:
        await self._start_move(msg)
        if msg.wait:
            await self._wait_axes((msg.axis,))

    async def _cmd_wait(self, msg: m.Wait) -> None:
        await self._wait_axes(msg.axes or tuple(self._pending))

    async def _cmd_read_axis(self, msg: m.ReadAxis) -> Any:
        t0 = time.perf_counter()
        out = await self._with_retries(self.devices.axis(msg.axis).read_position, f"read {msg.axis}", msg.retryable)
        self.ledger.add(Step("read", time.perf_counter() - t0))
        return out

    async def _cmd_read_encoder(self, msg: m.ReadEncoder) -> Any:
        if self.devices.encoder is None:
            raise EngineStateError("the plan reads an encoder, but the station has none")
        t0 = time.perf_counter()
        out = await self._with_retries(self.devices.encoder.read, "read encoder", msg.retryable)
        self.ledger.add(Step("read", time.perf_counter() - t0))
        return out

    async def _cmd_capture(self, msg: m.Capture) -> Any:
        if self.devices.camera is None:
            raise EngineStateError("the plan captures a frame, but the station has no camera")
        t0 = time.perf_counter()
        out = await self._with_retries(self._grab_checked, "grab frame", msg.retryable)
        self.ledger.add(Step("frame", time.perf_counter() - t0))
        return out

    async def _cmd_measure(self, msg: m.Measure) -> Any:
        if self.devices.measure is None:
            raise EngineStateError("the plan measures, but the station has no vision stage")
        t0 = time.perf_counter()
        out = await asyncio.to_thread(self.devices.measure, msg.image)
        self.ledger.add(Step("vision", time.perf_counter() - t0))
        return out

    async def _cmd_measure_surface(self, msg: m.MeasureSurface) -> Any:
        if self.devices.surface is None:
            raise EngineStateError("the plan inspects the surface, but the station has no defect detection")
        t0 = time.perf_counter()
        if msg.hole_places is None:
            out = await asyncio.to_thread(self.devices.surface, msg.image, blur_px=msg.blur_px)
        else:
            out = await asyncio.to_thread(self.devices.surface, msg.image, blur_px=msg.blur_px,
                                          hole_places=msg.hole_places)
        self.ledger.add(Step("vision", time.perf_counter() - t0))
        return out

    async def _cmd_emit(self, msg: m.Emit) -> None:
        """Nobody registered a command for the plan's documents: an event, nothing more."""
        self._emit("document", msg.name)

    async def _cmd_enable(self, msg: m.Enable) -> None:
        ax = self.devices.axis(msg.axis)
        await self._with_retries(lambda: ax.enable(msg.on), f"enable {msg.axis}", msg.retryable)

    async def _cmd_home(self, msg: m.Home) -> None:
        """Start the axis' homing; a ``Wait`` collects it with the homing timeout."""
        ax = self.devices.axis(msg.axis)
        await self._with_retries(ax.home, f"home {msg.axis}", msg.retryable)
        self._pending[msg.axis] = (msg, self.timeouts.home_s)
        self._at.pop(msg.axis, None)

    # ------------------------------------------------------------------ motion
    @staticmethod
    async def _send_move(ax, msg: m.Move) -> None:
        if msg.acceleration is None:
            await ax.move_to(msg.position, msg.velocity)
        else:
            await ax.move_to(msg.position, msg.velocity, acceleration=msg.acceleration)

    async def _resend(self, ax, msg: m.Msg) -> None:
        """A lost or overridden command sent again (absolute: idempotent)."""
        if isinstance(msg, m.Home):
            await ax.home()
        else:
            await self._send_move(ax, msg)

    async def _start_move(self, msg: m.Move) -> None:
        """Send a move and note it for its Wait: where from (read once per run), its
        timeout from the distance and speed, the ledger's entry."""
        ax = self.devices.axis(msg.axis)
        if msg.axis in self._pending:
            # a new move before the last was collected: the drive takes the new target
            self._pending.pop(msg.axis)
        start = self._at.get(msg.axis)
        t0 = time.perf_counter()
        if start is None:
            pos = await self._with_retries(ax.read_position, f"read {msg.axis}")
            start = float(pos) if isinstance(pos, (int, float)) else None
        await self._with_retries(lambda: self._send_move(ax, msg), f"move {msg.axis}", msg.retryable)
        v = msg.velocity if msg.velocity is not None else getattr(ax, "default_velocity", None)
        a = msg.acceleration if msg.acceleration is not None else getattr(ax, "default_acceleration", None)
        v = v if isinstance(v, (int, float)) else None
        a = a if isinstance(a, (int, float)) else None
        distance = None if start is None else abs(msg.position - start)
        self._pending[msg.axis] = (msg, self.timeouts.for_move(distance, v, a))
        self._at[msg.axis] = float(msg.position)
        self.ledger.add(Step("move", time.perf_counter() - t0, axis=msg.axis, start=start, target=float(msg.position),
                             velocity=v, acceleration=a))

    async def _wait_axes(self, axes: tuple[str, ...]) -> None:
        """Wait for each axis' move in turn; a move found lost or overridden (at rest
        short of its target, no fault) is sent again within the retry budget."""
        for name in axes:
            pending = self._pending.get(name)
            if pending is None:
                continue
            msg, timeout = pending
            ax = self.devices.axis(name)
            t0 = time.perf_counter()
            for attempt in range(self.retries + 1):
                try:
                    status = await ax.wait_in_position(timeout=timeout)
                except MoveInterrupted as exc:
                    # the absolute move is re-issued: a lost or stale command, not the machine
                    if attempt >= self.retries or not msg.retryable:
                        raise
                    self.retries_used += 1
                    self._emit("retry", f"move {name}: {exc} (move re-issued, {attempt + 1} of {self.retries})")
                    await self._with_retries(lambda: self._resend(ax, msg), f"move {name}", msg.retryable)
                    continue
                break
            self._pending.pop(name, None)
            if not isinstance(msg, m.Home):
                self.ledger.add(Step("wait", time.perf_counter() - t0, axis=name))
            self._check_estop(status)

    async def _grab_checked(self):
        frame = await self.devices.camera.grab()
        self.frame_check.check(frame, getattr(self.devices.camera, "name", "camera"))
        return frame

    async def axes_problem(self) -> str | None:
        """Why the axes cannot run a plan as they are (a fault that arrived while the
        engine was ready, a drive disabled or no longer referenced), or None."""
        for ax in (self.devices.z, self.devices.c):
            st = await self._with_retries(ax.status, f"status {getattr(ax, 'name', 'axis')}")
            name = getattr(ax, "name", "axis")
            if st.fault or st.estop or st.following_error:
                return f"{name} reports fault 0x{st.fault_code:04X}"
            if not st.enabled:
                return f"{name} is not enabled"
            if not st.homed:
                return f"{name} is not referenced"
            if ax is self.devices.c and abs(st.position) > C_WIND_LIMIT_DEG:
                # an endless table turns on from part to part; its drive counts in 32 bits
                # (596 turns at 0.0001 deg): homed at its nearest mark, the count starts again
                return f"{name} has wound {abs(st.position) / 360.0:.0f} turns"
        return None

    async def _with_retries(self, call: Callable[[], Awaitable[Any]], what: str, retryable: bool = True) -> Any:
        """``call()``, repeated on a transient error within the budget when the step is
        ``retryable`` (its message says so: ``Msg.retryable``)."""
        attempt = 0
        while True:
            try:
                out = call()
                return await out if _inspect.isawaitable(out) else out
            except TRANSIENT as exc:
                if not retryable or attempt >= self.retries:
                    raise
                attempt += 1
                self.retries_used += 1
                self._emit("retry", f"{what}: {exc} (retry {attempt} of {self.retries})")
                await asyncio.sleep(self.retry_backoff_s * attempt)

    def _check_estop(self, status) -> None:
        if getattr(status, "estop", False):
            raise DriveFault(int(FaultCode.ESTOP), "emergency stop", "station")

    async def _stop_axes(self) -> None:
        """Best effort: every axis gets a stop, whatever the others answer."""
        for ax in (self.devices.z, self.devices.c):
            try:
                await asyncio.wait_for(ax.stop(), timeout=2.0)
            except Exception:  # noqa: BLE001 - stopping must try every axis
                pass

    async def _fault(self, exc: BaseException) -> None:
        await self._stop_axes()
        code = getattr(exc, "code", None)
        estop = code == FaultCode.ESTOP
        reason = f"{type(exc).__name__}: {exc}"  # the driver's message names the device
        self.fault_code = code
        self._emit("fault", reason, error=type(exc).__name__, code=code)
        self._set(State.ESTOPPED if estop else State.FAULTED, reason)


def link_fault(engine: "Engine") -> bool:
    """Whether the engine's fault is a drive's communication watchdog: the drive stopped
    its axis because the station's heartbeats paused (a stalled station PC, a dropped
    link), which says nothing of the axis or the part. A job the station owns may be
    run once more after a reset; any other fault stands."""
    return engine.state == State.FAULTED and engine.fault_code == FaultCode.WATCHDOG_EXPIRED


def home_plan():
    """Homing as messages: enable and start homing each axis in turn (Z first: the
    endoscope leaves the bore before the table turns), then wait for both."""
    for axis in ("Z", "C"):
        yield m.Enable(axis, True)
        yield m.Home(axis)
    yield m.Wait(("Z", "C"))


#: message type -> command; every engine starts with these (``Engine.register_command``
#: adds or replaces one)
_DEFAULT_COMMANDS: dict[type, Command] = {
    m.Checkpoint: Engine._cmd_checkpoint,
    m.Progress: Engine._cmd_progress,
    m.Note: Engine._cmd_note,
    m.Settle: Engine._cmd_settle,
    m.Move: Engine._cmd_move,
    m.Wait: Engine._cmd_wait,
    m.ReadAxis: Engine._cmd_read_axis,
    m.ReadEncoder: Engine._cmd_read_encoder,
    m.Capture: Engine._cmd_capture,
    m.Measure: Engine._cmd_measure,
    m.MeasureSurface: Engine._cmd_measure_surface,
    m.Enable: Engine._cmd_enable,
    m.Home: Engine._cmd_home,
    m.Emit: Engine._cmd_emit,
}
