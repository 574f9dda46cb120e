"""The API's one long-lived station: session, store, engine, jobs, live data.

The app's lifespan opens one station session (``open_session``: the station from the
composition root, the store, the engine) and keeps it until shutdown, because the
station is one machine: a request must never build a second one. Inspections run as
background asyncio tasks on the server's event loop, one at a time, so an HTTP
request returns at once (202) while the axes move, and the MES polls the job.

The camera is shared between the sequencer and the live MJPEG stream through
:class:`SharedCamera`: one grab at a time, and the last frame kept, so that the
stream shows the sequencer's own frames while an inspection runs and grabs (slowly)
only when the station is idle.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import time
from dataclasses import dataclass
from typing import Any

from api.events import EventHub
from api.metrics import Metrics
from api.sessions import SessionStore
from api.singleflight import SingleFlight
from api.settings import Settings
from station.inspection.session import Session, open_session
from station.parts.spec import PartSpec
from station.sequencer.engine import EngineEvent, EngineStateError, PlanEnded, State
from station.store import DuplicateIdempotencyKey, StoreError
from station.store.tokens import TokenRepository

log = logging.getLogger("api")


class Busy(Exception):
    """The station is running a job already (answered 409)."""


class SharedCamera:
    """The station's camera behind a lock, remembering the last frame.

    The engine grabs through it (it replaces ``engine.devices.camera``), so the live
    stream can show the sequencer's frames without a second grab competing for the
    device mid-scan.
    """

    def __init__(self, camera):
        self.camera = camera
        self.name = getattr(camera, "name", "camera")
        self._lock = asyncio.Lock()
        self.last = None  # drivers.interfaces.Frame
        self.last_at = 0.0  # time.monotonic() of the last grab

    async def grab(self):
        async with self._lock:
            frame = await self.camera.grab()
            self.last, self.last_at = frame, time.monotonic()
            return frame

    async def connect(self) -> None:
        await self.camera.connect()

    async def close(self) -> None:
        await self.camera.close()


@dataclass
class Job:
    """The job running now: an inspection (kind "inspection") or homing ("home")."""

    kind: str
    task: asyncio.Task
    idempotency_key: str | None = None
    inspection_id: asyncio.Future | None = None  # resolves to the inspection's id
    started: float = 0.0


class _BeginNotifier:
    """The store, as the inspection service sees it, telling us the new inspection's id.

    The service creates the inspection record itself (``begin_inspection``) and only
    returns at the end; the API must answer the job order with the id at once. This
    thin proxy resolves a future with the id the moment the row is committed.
    """

    def __init__(self, store, future: asyncio.Future, loop: asyncio.AbstractEventLoop):
        self._store, self._future, self._loop = store, future, loop

    def begin_inspection(self, *args, **kwargs) -> str:
        try:
            iid = self._store.begin_inspection(*args, **kwargs)
        except BaseException as exc:  # noqa: BLE001 - the waiting request must hear of it
            self._loop.call_soon_threadsafe(_settle, self._future, None, exc)
            raise
        self._loop.call_soon_threadsafe(_settle, self._future, iid, None)
        return iid

    def __getattr__(self, name: str) -> Any:
        return getattr(self._store, name)


def _settle(future: asyncio.Future, value, exc) -> None:
    if future.done():
        return
    if exc is not None:
        future.set_exception(exc)
    else:
        future.set_result(value)


class StationRuntime:
    def __init__(self, settings: Settings):
        self.settings = settings
        self.hub = EventHub()
        self.metrics = Metrics()
        #: the operator panel's browser sessions (api/sessions.py)
        self.sessions = SessionStore()
        #: identical concurrent reads share one (polling clients)
        self.reads = SingleFlight()
        #: tokens whose hash was checked: sha256(token) -> record (api/auth.py)
        self.verified_tokens: dict[str, object] = {}
        self.session: Session | None = None
        self.store = None
        self.tokens: TokenRepository | None = None
        self.camera: SharedCamera | None = None
        self.job: Job | None = None
        self._stack = contextlib.AsyncExitStack()
        self._background: set[asyncio.Task] = set()

    # ------------------------------------------------------------------ life cycle
    async def open(self) -> None:
        s = self.settings
        self.session = await self._stack.enter_async_context(open_session(
            s.config, scenario=s.scenario, time_scale=s.time_scale, data_dir=s.data_dir, db_url=s.db_url,
            world=s.world))
        self.store = self.session.store
        self.tokens = TokenRepository(self.store)
        devices = self.session.engine.devices
        if devices.camera is not None:
            self.camera = SharedCamera(devices.camera)
            devices.camera = self.camera
        self.session.engine.subscribe(self._on_engine_event)
        s.parts_dir.mkdir(parents=True, exist_ok=True)

    async def close(self) -> None:
        """Abort a running job (the axes stop), end the live streams, close the station."""
        self.hub.close()
        if self.job is not None and not self.job.task.done():
            self.session.engine.abort("the API server is shutting down")
            with contextlib.suppress(BaseException):
                await asyncio.wait_for(asyncio.shield(self.job.task), timeout=10.0)
            if not self.job.task.done():
                self.job.task.cancel()
        for t in list(self._background):
            t.cancel()
        await self._stack.aclose()

    @property
    def engine(self):
        return self.session.engine

    @property
    def station(self):
        return self.session.station

    @property
    def busy(self) -> bool:
        return self.job is not None and not self.job.task.done()

    # ------------------------------------------------------------------ events
    def _on_engine_event(self, ev: EngineEvent) -> None:
        data: dict[str, Any] = {"state": ev.state.value, "text": ev.text}
        if ev.kind == "progress":
            data.update(done=ev.data.get("done"), total=ev.data.get("total"))
        if ev.kind in ("retry", "fault"):
            self.metrics.driver_errors.labels(ev.kind).inc()
        if ev.kind == "fault":
            data["error"] = ev.data.get("error")
        self.hub.publish(ev.kind, **data)

    def audit(self, who: str, what: str) -> None:
        """An entry of the audit log (the store's event log, kind "audit"): who changed what."""
        self.store.log_event("audit", f"{who}: {what}")

    # ------------------------------------------------------------------ jobs
    async def start_inspection(self, part: PartSpec, serial: str, order_id: str | None,
                               idempotency_key: str | None) -> tuple[str, bool]:
        """Start an inspection in the background; returns (inspection id, created).

        A known idempotency key returns the inspection that has it (created False) and
        starts nothing: a MES that retries a POST after a lost reply gets the same job.
        """
        if idempotency_key is not None:
            job = self.job
            if job is not None and job.idempotency_key == idempotency_key and job.inspection_id is not None:
                # the same order, still being started: its id, once the row exists
                return await asyncio.wait_for(asyncio.shield(job.inspection_id), timeout=30.0), False
            existing = await asyncio.to_thread(self.store.find_by_idempotency_key, idempotency_key)
            if existing is not None:
                return existing, False
        if self.busy:
            raise Busy(self._busy_text())
        loop = asyncio.get_running_loop()
        started = loop.create_future()
        service = self.session.service_for(part)
        service.store = _BeginNotifier(self.store, started, loop)
        task = loop.create_task(self._run_inspection(service, part, serial, order_id, idempotency_key, started))
        self.job = Job("inspection", task, idempotency_key, started, time.monotonic())
        self.metrics.busy.set(1)
        try:
            iid = await asyncio.wait_for(asyncio.shield(started), timeout=30.0)
        except DuplicateIdempotencyKey as dup:  # another process or a race: the same job
            return dup.inspection_id, False
        self.hub.publish("job", event="started", inspection_id=iid, part_number=part.part_number, serial=serial)
        return iid, True

    async def _run_inspection(self, service, part, serial, order_id, key, started: asyncio.Future) -> None:
        t0 = time.monotonic()
        iid = None
        try:
            outcome = await service.inspect(part, serial, order_id=order_id, idempotency_key=key)
            iid = outcome.id
            label = outcome.result if outcome.state == "complete" else outcome.state
            self.metrics.inspections.labels(label).inc()
            self.metrics.duration.observe(time.monotonic() - t0)
            self.hub.publish("job", event="finished", inspection_id=outcome.id, state=outcome.state,
                             result=outcome.result, reason=outcome.reason)
            self.hub.publish("result", **outcome.to_json())
        except asyncio.CancelledError:
            raise
        except Exception as exc:  # noqa: BLE001 - a job must end recorded, whatever broke
            log.exception("inspection failed")
            reason = f"{type(exc).__name__}: {exc}"
            if started.done() and not started.cancelled() and started.exception() is None:
                iid = started.result()
                await self._finish_if_running(iid, reason)
            _settle(started, None, exc)
            self.metrics.inspections.labels("faulted").inc()
            with contextlib.suppress(StoreError):
                await asyncio.to_thread(self.store.log_event, "alarm", f"inspection failed: {reason}", iid)
            self.hub.publish("job", event="finished", inspection_id=iid, state="faulted", result=None, reason=reason)
        finally:
            self.metrics.busy.set(0)

    async def _finish_if_running(self, iid: str, reason: str) -> None:
        with contextlib.suppress(StoreError, ValueError):
            rec = await asyncio.to_thread(self.store.get, iid)
            if rec.state == "running":
                await asyncio.to_thread(self.store.finish, iid, "faulted", None, reason)

    def _busy_text(self) -> str:
        job = self.job
        if job is None:
            return "busy"
        if job.kind == "inspection" and job.inspection_id is not None and job.inspection_id.done() \
                and job.inspection_id.exception() is None:
            return f"the station is running inspection {job.inspection_id.result()}; try again when it ends"
        return f"the station is busy ({job.kind}); try again when it ends"

    # ------------------------------------------------------------------ station commands
    async def command(self, name: str, who: str) -> dict:
        """pause, resume, stop, abort, reset, home; EngineStateError when the state
        does not allow it, Busy for reset/home while a job runs."""
        engine = self.engine
        if name in ("pause", "resume", "stop", "abort"):
            if name in ("pause", "stop", "abort") and engine.state not in (State.RUNNING, State.PAUSED, State.STOPPING):
                raise EngineStateError(f"cannot {name} while {engine.state.value}: nothing is running")
            if name == "resume" and engine.state not in (State.PAUSED, State.RUNNING):
                raise EngineStateError(f"cannot resume while {engine.state.value}: nothing is paused")
            if name == "abort":
                engine.abort(f"aborted by {who}")
            else:
                getattr(engine, name)()
        elif name in ("reset", "home"):
            if self.busy:
                raise Busy(self._busy_text())
            if name == "reset":
                try:
                    await asyncio.wait_for(engine.reset(), timeout=self.settings.command_timeout_s)
                except PlanEnded as ended:
                    raise EngineStateError(ended.reason) from None
            else:
                if engine.state not in (State.IDLE, State.READY):
                    raise EngineStateError(f"cannot home while {engine.state.value} (reset first)")
                task = asyncio.get_running_loop().create_task(self._home())
                self.job = Job("home", task, started=time.monotonic())
                self.metrics.busy.set(1)
        else:
            raise ValueError(f"unknown command {name!r}")
        with contextlib.suppress(StoreError):
            await asyncio.to_thread(self.store.log_event, "command", f"{name} by {who}")
        return self.station_status()

    async def _home(self) -> None:
        try:
            await asyncio.wait_for(self.engine.home(), timeout=self.engine.timeouts.home_s * 2)
        except (PlanEnded, asyncio.TimeoutError, EngineStateError) as exc:
            with contextlib.suppress(StoreError):
                await asyncio.to_thread(self.store.log_event, "alarm", f"homing failed: {exc}")
        finally:
            self.metrics.busy.set(0)

    def station_status(self) -> dict:
        e = self.engine
        done, total, text = e.progress
        job = None
        if self.job is not None:
            iid = None
            f = self.job.inspection_id
            if f is not None and f.done() and not f.cancelled() and f.exception() is None:
                iid = f.result()
            job = {"kind": self.job.kind, "inspection_id": iid, "running": not self.job.task.done()}
        return {"state": e.state.value, "reason": e.reason, "progress": {"done": done, "total": total, "text": text},
                "mode": self.station.mode, "busy": self.busy, "job": job}
