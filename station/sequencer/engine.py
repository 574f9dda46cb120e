"""The run engine: one state machine that carries out plans on the station's devices.

States (``State``): idle, homing, ready, running, paused, stopping, aborting,
faulted, estopped. Transitions:

    idle --home--> homing --> ready --run--> running --> ready (plan done)
    running --pause--> (at the next checkpoint) paused --resume--> running
    running/paused --stop--> stopping (at the next checkpoint) --> ready, plan ends "stopped"
    running/paused --abort--> aborting (axes stopped at once) --> ready, plan ends "aborted"
    any --driver fault--> faulted (axes stopped, reason kept) --reset--> idle
    any --e-stop seen--> estopped --reset (after release)--> idle

Transient driver errors (timeout, lost link, garbled reply) are retried within a
budget for idempotent steps; a drive fault, a following error or an exhausted
budget faults the engine. The engine, not the plan, talks to drivers.
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
        self.progress: tuple[int, int, str] = (0, 0, "")
        self._listeners: list[Callable[[EngineEvent], None]] = []
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
        #: per axis: the move under way that a Wait collects, and its timeout
        self._pending: dict[str, tuple[m.Move, float]] = {}

    # ------------------------------------------------------------------ events
    def subscribe(self, fn: Callable[[EngineEvent], None]) -> None:
        self._listeners.append(fn)

    def unsubscribe(self, fn: Callable[[EngineEvent], None]) -> None:
        """Stop calling ``fn``; a listener that is not subscribed is ignored."""
        try:
            self._listeners.remove(fn)
        except ValueError:
            pass

    def _emit(self, kind: str, text: str = "", **data) -> None:
        ev = EngineEvent(time.time(), kind, self.state, text, data)
        for fn in list(self._listeners):
            try:
                fn(ev)
            except Exception:  # noqa: BLE001 - a broken listener must not stop the machine
                pass

    def _set(self, state: State, reason: str = "") -> None:
        self.state = state
        if reason:
            self.reason = reason
        self._emit("state", reason)

    # ------------------------------------------------------------------ commands
    async def home(self) -> None:
        """Enable and home both axes; idle (or ready) -> homing -> ready."""
        if self.state not in (State.IDLE, State.READY):
            raise EngineStateError(f"cannot home while {self.state.value}")
        self._set(State.HOMING)
        try:
            for ax in (self.devices.z, self.devices.c):
                await self._with_retries(lambda ax=ax: ax.enable(True), "enable")
                await self._with_retries(ax.home, "home")
            for ax in (self.devices.z, self.devices.c):
                await ax.wait_in_position(timeout=self.timeouts.home_s)
        except DriverError as exc:
            await self._fault(exc)
            raise PlanEnded("faulted", self.reason) from exc
        self._set(State.READY, "homed")

    def pause(self) -> None:
        if self.state == State.RUNNING:
            self._pause_requested = True
            self._resume.clear()

    def resume(self) -> None:
        if self.state in (State.PAUSED, State.RUNNING):
            self._pause_requested = False
            self._resume.set()

    def stop(self) -> None:
        """Controlled stop: the plan ends at its next checkpoint, the current move completes."""
        if self.state in (State.RUNNING, State.PAUSED):
            self._stop_requested = True
            self._resume.set()

    def abort(self, reason: str = "aborted by operator") -> None:
        """Stop the axes now and end the plan as aborted."""
        if self.state in (State.RUNNING, State.PAUSED, State.STOPPING):
            self._abort_requested = reason
            self._resume.set()
            if self._task is not None:
                self._task.cancel()

    async def reset(self) -> None:
        """Acknowledge a fault or a released e-stop: reset the drives, back to idle (home again)."""
        if self.state not in (State.FAULTED, State.ESTOPPED, State.IDLE, State.READY):
            raise EngineStateError(f"cannot reset while {self.state.value}")
        for ax in (self.devices.z, self.devices.c):
            try:
                # a link that dropped with the fault reconnects here: retried like any step
                await self._with_retries(ax.reset_fault, f"reset {getattr(ax, 'name', 'axis')}")
            except DriverError as exc:
                self._set(State.FAULTED, f"reset failed on {getattr(ax, 'name', 'axis')}: {exc}")
                raise PlanEnded("faulted", self.reason) from exc
        self.reason = ""
        self._set(State.IDLE, "reset")

    # ------------------------------------------------------------------ running plans
    async def run(self, plan: Generator[m.Msg, Any, Any]) -> Any:
        """Carry out ``plan``; returns its return value, or raises :class:`PlanEnded`."""
        if self.state != State.READY:
            raise EngineStateError(f"cannot run a plan while {self.state.value} (home first)")
        self._stop_requested = False
        self._abort_requested = None
        self._pause_requested = False
        self._resume.set()
        self.retries_used = 0
        self.ledger = CycleLedger()
        self._at = {}
        self._pending = {}
        self._set(State.RUNNING)
        self._task = asyncio.create_task(self._drive(plan))
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

    async def _drive(self, plan) -> Any:
        result: Any = None
        while True:
            t0 = time.perf_counter()
            try:
                msg = plan.send(result)
            except StopIteration as done:
                self.ledger.add(Step("plan", time.perf_counter() - t0))
                self._set(State.READY, "plan complete")
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

    async def _execute(self, msg: m.Msg) -> Any:
        d = self.devices
        if isinstance(msg, m.Checkpoint):
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
            return None
        if isinstance(msg, m.Progress):
            self.progress = (msg.done, msg.total, msg.text)
            self._emit("progress", msg.text, done=msg.done, total=msg.total)
            return None
        if isinstance(msg, m.Note):
            self._emit("note", msg.text)
            return None
        if isinstance(msg, m.Settle):
            t0 = time.perf_counter()
            await self._sleep(msg.seconds)
            self.ledger.add(Step("settle", time.perf_counter() - t0, seconds=msg.seconds))
            return None
        if isinstance(msg, m.Move):
            await self._start_move(msg)
            if msg.wait:
                await self._wait_axes((msg.axis,))
            return None
        if isinstance(msg, m.Wait):
            await self._wait_axes(msg.axes or tuple(self._pending))
            return None
        if isinstance(msg, m.ReadAxis):
            t0 = time.perf_counter()
            out = await self._with_retries(d.axis(msg.axis).read_position, f"read {msg.axis}")
            self.ledger.add(Step("read", time.perf_counter() - t0))
            return out
        if isinstance(msg, m.ReadEncoder):
            if d.encoder is None:
                raise EngineStateError("the plan reads an encoder, but the station has none")
            t0 = time.perf_counter()
            out = await self._with_retries(d.encoder.read, "read encoder")
            self.ledger.add(Step("read", time.perf_counter() - t0))
            return out
        if isinstance(msg, m.Capture):
            if d.camera is None:
                raise EngineStateError("the plan captures a frame, but the station has no camera")
            t0 = time.perf_counter()
            out = await self._with_retries(self._grab_checked, "grab frame")
            self.ledger.add(Step("frame", time.perf_counter() - t0))
            return out
        if isinstance(msg, m.Measure):
            if d.measure is None:
                raise EngineStateError("the plan measures, but the station has no vision stage")
            t0 = time.perf_counter()
            out = await asyncio.to_thread(d.measure, msg.image)
            self.ledger.add(Step("vision", time.perf_counter() - t0))
            return out
        raise TypeError(f"unknown message {msg!r}")

    @staticmethod
    async def _send_move(ax, msg: m.Move) -> None:
        if msg.acceleration is None:
            await ax.move_to(msg.position, msg.velocity)
        else:
            await ax.move_to(msg.position, msg.velocity, acceleration=msg.acceleration)

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
        await self._with_retries(lambda: self._send_move(ax, msg), f"move {msg.axis}")
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
                    if attempt >= self.retries:
                        raise
                    self.retries_used += 1
                    self._emit("retry", f"move {name}: {exc} (move re-issued, {attempt + 1} of {self.retries})")
                    await self._with_retries(lambda: self._send_move(ax, msg), f"move {name}")
                    continue
                break
            self._pending.pop(name, None)
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

    async def _with_retries(self, call: Callable[[], Awaitable[Any]], what: str) -> Any:
        attempt = 0
        while True:
            try:
                out = call()
                return await out if _inspect.isawaitable(out) else out
            except TRANSIENT as exc:
                if attempt >= self.retries:
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

    async def _fault(self, exc: Exception) -> None:
        await self._stop_axes()
        code = getattr(exc, "code", None)
        estop = code == FaultCode.ESTOP
        reason = f"{type(exc).__name__}: {exc}"  # the driver's message names the device
        self._emit("fault", reason, error=type(exc).__name__, code=code)
        self._set(State.ESTOPPED if estop else State.FAULTED, reason)
