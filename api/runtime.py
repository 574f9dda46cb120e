"""The API's one long-lived station: session, store, engine, jobs, live data.

The app's lifespan opens one station session (``open_session``: the station from the
composition root, the store, the engine) and keeps it until shutdown, because the
station is one machine: a request must never build a second one.

The station runs on its own event loop in a thread of this process (the "station
thread", :mod:`api.station_thread`): the engine, the drivers with their heartbeats,
the encoder, the camera and every inspection. The API's loop (uvicorn's) only
answers requests; it reaches the station through thread-safe calls
(``run_coroutine_threadsafe`` + ``wrap_future``) and hears from it through
``api_loop.call_soon_threadsafe`` (engine events for SSE and the metrics, camera
frames for MJPEG). However busy the web side is, the drives' heartbeats keep time.
Inspections run as background jobs on the station loop, one at a time, so an HTTP
request returns at once (202) while the axes move, and the MES polls the job.

The camera is shared between the sequencer and the live MJPEG stream through
:class:`SharedCamera` (on the station loop: one grab at a time, the last frame kept)
and :class:`LiveCamera` (on the API loop: the last frame handed over, and a grab
asked of the station loop), so that the stream shows the sequencer's own frames
while an inspection runs and grabs (slowly) only when the station is idle.

What runs where: plain reads of the engine's state, reason and progress (one
attribute each, atomic) are made from the API loop; whatever awaits a device,
touches the engine's asyncio objects (pause, abort, reset, home) or changes what the
station measures with (model, scale) runs on the station loop.
"""

from __future__ import annotations

import asyncio
import concurrent.futures
import contextlib
import functools
import logging
import time
from collections import OrderedDict
from dataclasses import dataclass, field
from datetime import datetime, timezone
from typing import Any, Callable

from api.events import EventHub
from api.metrics import Metrics
from api.ratelimit import WriteLimiter
from api.sessions import SessionStore
from api.singleflight import SingleFlight
from api.settings import Settings
from api.station_thread import StationThread, to_loop
from station.inspection.documents import CheckDocument, FrameDocument, HoleDocument, InspectionStart
from station.inspection.session import Session
from station.runtime import open_session
from station.parts.spec import PartSpec
from station.sequencer.engine import EngineEvent, EngineStateError, PlanEnded
from station.store import DuplicateIdempotencyKey, StoreError
from station.store.repository import finite_json
from station.store.tokens import TokenRepository

log = logging.getLogger("api")


#: how long a new order waits for an inspection whose record already reads ended (s)
ENDING_GRACE_S = 10.0


class Busy(Exception):
    """The station is running a job already (answered 409)."""


class SharedCamera:
    """The station's camera behind a lock, remembering the last frame (station loop).

    The engine grabs through it (it replaces ``engine.devices.camera``), so the live
    stream can show the sequencer's frames without a second grab competing for the
    device mid-scan. Every frame is also handed to ``on_frame(frame, at)`` (called on
    the station loop; the runtime passes it on to the API loop).
    """

    def __init__(self, camera, on_frame: Callable[[Any, float], None] | None = None):
        self.camera = camera
        self.name = getattr(camera, "name", "camera")
        self._lock = asyncio.Lock()
        self.on_frame = on_frame
        self.last = None  # drivers.interfaces.Frame
        self.last_at = 0.0  # time.monotonic() of the last grab

    @property
    def timing(self):
        """The camera's sensor timing (the cycle time's frames), as the camera states it."""
        return getattr(self.camera, "timing", None)

    async def grab(self):
        async with self._lock:
            frame = await self.camera.grab()
            self.last, self.last_at = frame, time.monotonic()
        if self.on_frame is not None:
            self.on_frame(frame, self.last_at)
        return frame

    async def connect(self) -> None:
        await self.camera.connect()

    async def close(self) -> None:
        await self.camera.close()


class LiveCamera:
    """The camera as the API loop sees it: the last frame the station thread handed
    over (``last``, ``last_at``) and a grab that runs on the station loop."""

    def __init__(self, thread: StationThread, shared: SharedCamera):
        self._thread, self._shared = thread, shared
        self.name = shared.name
        self.last = None
        self.last_at = 0.0

    def frame_arrived(self, frame, at: float) -> None:
        """On the API loop (``call_soon_threadsafe`` from the station thread)."""
        if at >= self.last_at:
            self.last, self.last_at = frame, at

    async def grab(self):
        return await self._thread.call(self._shared.grab())


@dataclass
class Job:
    """The job running now: an inspection (kind "inspection"), a check on the master
    ("check") or homing ("home").

    ``task`` is the ``concurrent.futures.Future`` of its coroutine on the station
    loop: ``done()`` and ``cancel()`` are safe from the API loop."""

    kind: str
    task: concurrent.futures.Future
    idempotency_key: str | None = None
    inspection_id: asyncio.Future | None = None  # resolves to the inspection's id (API loop)
    started: float = 0.0


def document_event(doc) -> tuple[str, dict] | None:
    """An inspection document as a live event (``frame``, ``hole``, ``characteristic``:
    the SSE ``check`` event is a check on the master), its name and data; None for the
    documents the hub has its own events for (start and stop: ``job`` and ``result``)."""
    if isinstance(doc, FrameDocument) and doc.frame is not None:
        f = doc.frame
        return "frame", {
            "inspection_id": doc.inspection_id, "hole": doc.hole, "index": doc.index,
            "axial_mm": f.axial_mm, "angle_deg": f.angle_deg,
            "diameter_mm": f.diameter_mm, "confidence": f.confidence,
            "grating_mm": f.grating_mm, "z_cmd_mm": f.z_cmd_mm, "c_cmd_deg": f.c_cmd_deg}
    if isinstance(doc, HoleDocument) and doc.hole is not None:
        h = doc.hole
        return "hole", {
            "inspection_id": doc.inspection_id, "hole": h.name, "found": h.found,
            "position_mm": h.position_mm, "position_u_mm": h.position_u_mm,
            "diameter_mm": h.diameter_mm, "diameter_u_mm": h.diameter_u_mm,
            "angle_deg": h.angle_deg, "frames": len(h.frames), "reason": h.reason}
    if isinstance(doc, CheckDocument) and doc.characteristic is not None:
        c = doc.characteristic
        return "characteristic", {
            "inspection_id": doc.inspection_id, "id": c.id, "nominal": c.nominal,
            "lower_limit": c.lower_limit, "upper_limit": c.upper_limit, "measured": c.measured,
            "uncertainty_k2": c.uncertainty_k2, "pass": c.passed}
    return None


class _StartWatcher:
    """Tells the API the new inspection's id the moment its record exists.

    Subscribed to the session's documents for one job: the store writer (a required
    subscriber, before this one) begins the record on the start document, then this
    resolves a future of the API loop with the id (it runs on the station loop: it
    hops). A refused start never reaches it; the job's failure settles the future.
    """

    def __init__(self, future: asyncio.Future, loop: asyncio.AbstractEventLoop):
        self._future, self._loop = future, loop
        self.iid: str | None = None

    def __call__(self, doc) -> None:
        if self.iid is None and isinstance(doc, InspectionStart):
            self.iid = doc.inspection_id
            with contextlib.suppress(RuntimeError):
                self._loop.call_soon_threadsafe(_settle, self._future, self.iid, None)


def _settle(future: asyncio.Future, value, exc) -> None:
    if future.done():
        return
    if exc is not None:
        future.set_exception(exc)
    else:
        future.set_result(value)


@dataclass
class _Ended:
    """How a job's coroutine on the station loop ended, for the API loop to publish."""

    outcome: Any = None  # InspectionOutcome (MasterCheckOutcome for a check) when it completed
    seconds: float = 0.0
    iid: str | None = None
    reason: str | None = None  # set when it failed
    #: the station's watch after the job (StationWatch.state(), taken on the station loop)
    monitor: dict | None = None
    #: a check out of control: the model proposal it made (station.monitor.proposals.Proposal)
    proposal: Any = None


#: master checks whose results the API keeps (in memory, newest; the inspection itself is in the store)
CHECKS_KEPT = 100


def _now() -> str:
    return datetime.now(timezone.utc).isoformat()


@dataclass
class CheckRecord:
    """A check on the certified master as the API shows it (``GET /checks/{id}``): its
    id is the master inspection's; ``result`` is ``MasterCheckOutcome.to_json()`` once it
    has ended (the twin's truth left out)."""

    id: str
    master_id: str
    state: str = "running"  # running, then the master inspection's: complete | aborted | faulted
    started_at: str = field(default_factory=_now)
    finished_at: str | None = None
    reason: str | None = None
    result: dict | None = None
    proposal_id: str | None = None
    kind: str = "master"

    def to_json(self) -> dict:
        r = self.result
        return {"id": self.id, "kind": self.kind, "master_id": self.master_id, "state": self.state,
                "in_control": None if r is None else r["in_control"], "reason": self.reason,
                "started_at": self.started_at, "finished_at": self.finished_at, "result": r,
                "proposal_id": self.proposal_id,
                "links": {"self": f"/api/v1/checks/{self.id}", "inspection": f"/api/v1/inspections/{self.id}",
                          **({"proposal": f"/api/v1/model-proposals/{self.proposal_id}"} if self.proposal_id else {})}}


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
        #: token id -> monotonic time its revocation was last read as "not revoked"
        self.token_checked: dict[int, float] = {}
        #: writes per token (api/ratelimit.py), applied by api.auth.authenticate
        self.write_limiter = WriteLimiter(settings.write_rate_per_s, settings.write_burst)
        self.records = None
        #: the station's own loop and thread (api/station_thread.py)
        self.thread = StationThread()
        self.api_loop: asyncio.AbstractEventLoop | None = None
        self._to_api: Callable[..., None] = lambda fn, *args: None
        self.session: Session | None = None
        self.store = None
        self.tokens: TokenRepository | None = None
        self.camera: LiveCamera | None = None
        self.job: Job | None = None
        #: master checks started by this process, by id (API loop only; the last CHECKS_KEPT)
        self.checks: OrderedDict[str, CheckRecord] = OrderedDict()

    # ------------------------------------------------------------------ life cycle
    async def open(self) -> None:
        s = self.settings
        self.api_loop = asyncio.get_running_loop()
        self._to_api = to_loop(self.api_loop)
        self.session = await self.thread.start(
            lambda: open_session(s.config, scenario=s.scenario, time_scale=s.time_scale, data_dir=s.data_dir,
                                 db_url=s.db_url, world=s.world, station_id=s.station_id),
            self._setup_station)
        self.store = self.session.store
        from api.records import RecordCache
        from api.routes.common import blocking

        #: inspection records, read once per committed change (api/records.py)
        self.records = RecordCache(self.store, blocking)
        self.tokens = TokenRepository(self.store)
        s.parts_dir.mkdir(parents=True, exist_ok=True)

    def _setup_station(self, session: Session) -> None:
        """On the station loop, once the session is open: the shared camera, the engine's listener."""
        devices = session.engine.devices
        if devices.camera is not None:
            shared = SharedCamera(devices.camera)
            live = LiveCamera(self.thread, shared)
            shared.on_frame = lambda frame, at: self._to_api(live.frame_arrived, frame, at)
            devices.camera = shared
            self.camera = live
        session.engine.subscribe(self._on_engine_event)
        session.documents.subscribe(self._on_document)

    async def close(self) -> None:
        """Abort a running job (the axes stop), end the live streams, close the station
        and end its thread."""
        self.hub.close()
        job = self.job
        if job is not None and not job.task.done() and self.thread.alive:
            with contextlib.suppress(BaseException):
                await self.thread.run(self.session.engine.abort, "the API server is shutting down")
            with contextlib.suppress(BaseException):
                await asyncio.wait_for(asyncio.shield(asyncio.wrap_future(job.task)), timeout=10.0)
            if not job.task.done():
                job.task.cancel()
        await self.thread.stop()

    @property
    def engine(self):
        return self.session.engine

    @property
    def station(self):
        return self.session.station

    @property
    def busy(self) -> bool:
        return self.job is not None and not self.job.task.done()

    async def on_station(self, coro, timeout: float | None = None):
        """Await ``coro`` run on the station loop (a device read, an engine call)."""
        return await self.thread.call(coro, timeout=timeout)

    # ------------------------------------------------------------------ events
    def _on_engine_event(self, ev: EngineEvent) -> None:
        """The engine's listener: called on the station loop, published on the API loop."""
        self._to_api(self._publish_engine_event, ev)

    def _publish_engine_event(self, ev: EngineEvent) -> None:
        data: dict[str, Any] = {"state": ev.state.value, "text": ev.text}
        if ev.kind == "progress":
            data.update(done=ev.data.get("done"), total=ev.data.get("total"))
        if ev.kind in ("retry", "fault"):
            self.metrics.driver_errors.labels(ev.kind).inc()
        if ev.kind == "fault":
            data["error"] = ev.data.get("error")
        self.hub.publish(ev.kind, **data)

    def _on_document(self, doc) -> None:
        """The SSE hub as a subscriber of the inspections' documents (called on the
        station loop; the event goes out on the API loop): each measurement frame, hole
        and characteristic as the inspection finds it, before its result."""
        event = document_event(doc)
        if event is not None:
            name, data = event
            # JSON has no NaN: a hole not found has no diameter (null)
            self._to_api(functools.partial(self.hub.publish, name, **finite_json(data)))

    def audit(self, who: str, what: str) -> None:
        """An entry of the audit log (the store's event log, kind "audit"): who changed what."""
        self.store.log_event("audit", f"{who}: {what}")

    def start_job(self, kind: str, coro, on_end: Callable[[concurrent.futures.Future], None], *,
                   key: str | None = None, started: asyncio.Future | None = None) -> Job:
        """Run ``coro`` on the station loop as the job; ``on_end(future)`` on the API loop
        once it is done (so whoever hears of the end finds the station no longer busy)."""
        fut = self.thread.submit(coro)
        job = Job(kind, fut, key, started, time.monotonic())
        self.job = job
        self.metrics.busy.set(1)
        fut.add_done_callback(lambda f: self._to_api(self._job_done, job, on_end, f))
        return job

    def _job_done(self, job: Job, on_end, fut: concurrent.futures.Future) -> None:
        self.metrics.busy.set(0)
        try:
            on_end(fut)
        except Exception:  # noqa: BLE001 - publishing must not break the loop's callback
            log.exception("publishing the end of a %s job failed", job.kind)

    # ------------------------------------------------------------------ jobs
    async def start_inspection(self, part: PartSpec, serial: str, order_id: str | None,
                               idempotency_key: str | None, surface: bool | None = None) -> tuple[str, bool]:
        """Start an inspection in the background; returns (inspection id, created).
        ``surface``: scan the whole surface too (None: as the part spec says).

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
            await self._await_ending_inspection()
        if self.busy:
            raise Busy(self.busy_text())
        started = asyncio.get_running_loop().create_future()
        self.start_job("inspection", self._run_inspection(part, serial, order_id, idempotency_key, started, surface),
                        self._inspection_ended, key=idempotency_key, started=started)
        try:
            iid = await asyncio.wait_for(asyncio.shield(started), timeout=30.0)
        except DuplicateIdempotencyKey as dup:  # another process or a race: the same job
            return dup.inspection_id, False
        self.hub.publish("job", event="started", job="inspection", inspection_id=iid, part_number=part.part_number,
                         serial=serial)
        return iid, True

    async def _run_inspection(self, part, serial, order_id, key, started: asyncio.Future,
                              surface: bool | None = None) -> _Ended:
        """On the station loop. Store writes go to this loop's own worker threads."""
        t0 = time.monotonic()
        watcher = _StartWatcher(started, self.api_loop)
        unsubscribe = self.session.documents.subscribe(watcher)
        try:
            service = self.session.service_for(part)
            outcome = await service.inspect(part, serial, order_id=order_id, idempotency_key=key, surface=surface)
            return _Ended(outcome=outcome, seconds=time.monotonic() - t0, iid=outcome.id,
                          monitor=self.session.watch.state())
        except asyncio.CancelledError:
            raise
        except Exception as exc:  # noqa: BLE001 - a job must end recorded, whatever broke
            log.exception("inspection failed")
            reason = f"{type(exc).__name__}: {exc}"
            iid = watcher.iid
            if iid is not None:
                await self._finish_if_running(iid, reason)
            self._to_api(_settle, started, None, exc)
            with contextlib.suppress(StoreError):
                await asyncio.to_thread(self.store.log_event, "alarm", f"inspection failed: {reason}", iid)
            return _Ended(iid=iid, reason=reason)
        finally:
            unsubscribe()

    @staticmethod
    def _ended_of(fut: concurrent.futures.Future) -> _Ended | None:
        """What a finished job's future holds (an exception as its reason); None if cancelled."""
        if fut.cancelled():
            return None
        if fut.exception() is not None:
            return _Ended(reason=f"{type(fut.exception()).__name__}: {fut.exception()}")
        return fut.result()

    def _inspection_ended(self, fut: concurrent.futures.Future) -> None:
        """On the API loop: the metrics and the events of a finished inspection."""
        ended = self._ended_of(fut)
        if ended is None:
            return
        outcome = ended.outcome
        if outcome is not None:
            label = outcome.result if outcome.state == "complete" else outcome.state
            self.metrics.inspections.labels(label).inc()
            self.metrics.duration.observe(ended.seconds)
            self._monitor_news("inspection", outcome.id, outcome.alarms, ended.monitor)
            self.hub.publish("job", event="finished", job="inspection", inspection_id=outcome.id,
                             state=outcome.state, result=outcome.result, reason=outcome.reason)
            self.hub.publish("result", **outcome.to_json())
        else:
            self.metrics.inspections.labels("faulted").inc()
            self.hub.publish("job", event="finished", job="inspection", inspection_id=ended.iid, state="faulted",
                             result=None, reason=ended.reason)

    # ------------------------------------------------------------------ the station's watch
    def monitor_state(self) -> dict:
        """The station's watch as the MES reads it (``StationWatch.state()``: single
        attributes, read from the API loop like the engine's state)."""
        return self.session.watch.state()

    def update_monitor_metrics(self, state: dict | None = None) -> None:
        state = state if state is not None else self.monitor_state()
        self.metrics.needs_check.set(1 if state["needs_check"] else 0)

    def _monitor_news(self, source: str, iid: str | None, alarms, state: dict | None) -> None:
        """On the API loop, after an inspection or a check: the metrics, and an ``alarm``
        event when the charts raised any."""
        self.update_monitor_metrics(state)
        if alarms:
            self.metrics.monitor_alarms.inc(len(alarms))
            self.hub.publish("alarm", source=source, inspection_id=iid, alarms=[a.to_json() for a in alarms],
                             needs_check=bool(state and state["needs_check"]),
                             reason=state["reason"] if state else None)

    def _keep_check(self, rec: CheckRecord) -> CheckRecord:
        self.checks[rec.id] = rec
        self.checks.move_to_end(rec.id)
        while len(self.checks) > CHECKS_KEPT:
            self.checks.popitem(last=False)
        return rec

    async def start_check(self, cert, family: PartSpec) -> CheckRecord:
        """Start a check on the certified master (``cert``, of the part family
        ``family``) as the job; returns its record (state running) once the master's
        inspection has its id. Busy while another job runs."""
        if self.busy:
            raise Busy(self.busy_text())
        started = asyncio.get_running_loop().create_future()
        self.start_job("check", self._run_check(cert, family, started),
                        lambda fut: self._check_ended(fut, cert.master_id), started=started)
        iid = await asyncio.wait_for(asyncio.shield(started), timeout=30.0)
        rec = self.checks.get(iid) or self._keep_check(CheckRecord(iid, cert.master_id))
        self.hub.publish("job", event="started", job="check", inspection_id=iid, part_number=cert.master_id,
                         serial=cert.master_id)
        return rec

    async def _run_check(self, cert, family: PartSpec, started: asyncio.Future) -> _Ended:
        """On the station loop: the session's check on the master, then (out of control)
        a model proposal from the checks since the last in control, as the campaign
        makes it. The master inspection's id reaches the waiting request from its start
        document, as soon as its record exists."""
        t0 = time.monotonic()
        session = self.session
        notifier = _StartWatcher(started, self.api_loop)
        unsubscribe = session.documents.subscribe(notifier)
        try:
            chk = await session.check_master(cert, family)
        except asyncio.CancelledError:
            raise
        except Exception as exc:  # noqa: BLE001 - a job must end recorded, whatever broke
            log.exception("master check failed")
            reason = f"{type(exc).__name__}: {exc}"
            iid = notifier.iid
            if iid is not None:
                await self._finish_if_running(iid, reason)
            self._to_api(_settle, started, None, exc)
            with contextlib.suppress(StoreError):
                await asyncio.to_thread(self.store.log_event, "alarm", f"master check failed: {reason}", iid)
            return _Ended(iid=iid, reason=reason, monitor=session.watch.state())
        finally:
            unsubscribe()
        proposal = None
        if chk.alarms:
            try:
                proposal = await session.propose(chk.alarms[0].reason, {h.id: h.position_mm for h in cert.holes})
            except Exception:  # noqa: BLE001 - the check stands; the proposal's trouble is logged
                log.exception("a model proposal from master check %s failed", chk.inspection.id)
        return _Ended(outcome=chk, seconds=time.monotonic() - t0, iid=chk.inspection.id,
                      monitor=session.watch.state(), proposal=proposal)

    def _check_ended(self, fut: concurrent.futures.Future, master_id: str) -> None:
        """On the API loop: the check's record, the metrics and the events."""
        ended = self._ended_of(fut)
        if ended is None:
            return
        chk = ended.outcome
        if ended.iid is None:  # it never got as far as a record: nothing to keep
            self.hub.publish("job", event="finished", job="check", inspection_id=None, state="faulted",
                             result=None, reason=ended.reason)
            return
        rec = self.checks.get(ended.iid) or self._keep_check(CheckRecord(ended.iid, master_id))
        rec.finished_at = _now()
        if chk is None:
            rec.state, rec.reason = "faulted", ended.reason
            self.update_monitor_metrics(ended.monitor)
        else:
            # the master inspection's own state: complete, or aborted / faulted (then out of control)
            rec.state, rec.reason = chk.inspection.state, chk.inspection.reason or None
            rec.result = chk.to_json(with_truth=False)
            rec.proposal_id = ended.proposal.id if ended.proposal is not None else None
            self._monitor_news("check", rec.id, chk.alarms, ended.monitor)
        self.hub.publish("job", event="finished", job="check", inspection_id=rec.id, state=rec.state,
                         result=None if chk is None else chk.inspection.result, reason=rec.reason)
        if ended.proposal is not None:
            p = ended.proposal
            self.hub.publish("proposal", event="proposed", id=p.id, state=p.state, reason=p.reason,
                             terms=[c.term for c in p.changes])
        # last: whoever waits for the check's end finds its alarm and proposal published
        self.hub.publish("check", event="finished", id=rec.id, master_id=rec.master_id, state=rec.state,
                         in_control=None if chk is None else chk.in_control, proposal_id=rec.proposal_id)

    async def decide_proposal(self, proposal_id: str, approve: bool, who: str, note: str = ""):
        """An engineer's decision on a model proposal, made on the station loop (approved:
        the station's model from the next inspection); not while a job runs (Busy).
        Returns (proposal, the station's model version after it)."""
        if self.busy:
            raise Busy(f"cannot decide on a model proposal while a job runs: {self.busy_text()}")

        async def decide():
            p = await self.session.decide(proposal_id, approve, who, note)
            return p, self.session.model_version

        p, version = await self.thread.call(decide())
        self.update_monitor_metrics()
        self.hub.publish("proposal", event=p.state, id=p.id, state=p.state, decided_by=p.decided_by,
                         model_version=version)
        return p, version

    async def _await_ending_inspection(self, grace_s: float = ENDING_GRACE_S) -> None:
        """Wait for the running job if it is an inspection whose record already reads
        ended: it is only wrapping up (the station loop returns after the record is
        written), and a MES that polled the inspection to its end and sends the next order
        at once must not be refused for that.  Returns at once otherwise, or after
        ``grace_s`` if the wrap-up takes longer."""
        job = self.job
        if job is None or job.kind != "inspection" or job.inspection_id is None or not job.inspection_id.done() \
                or job.inspection_id.cancelled() or job.inspection_id.exception() is not None:
            return
        try:
            rec = await asyncio.to_thread(self.store.get, job.inspection_id.result())
        except (StoreError, ValueError):
            return
        if rec is None or rec.state == "running":
            return
        # asyncio.wait neither raises what the job raised nor cancels it on the timeout
        ended = asyncio.wrap_future(job.task)
        ended.add_done_callback(lambda f: f.cancelled() or f.exception())  # retrieved: no warning
        await asyncio.wait({ended}, timeout=grace_s)

    async def _finish_if_running(self, iid: str, reason: str) -> None:
        with contextlib.suppress(StoreError, ValueError):
            rec = await asyncio.to_thread(self.store.get, iid)
            if rec.state == "running":
                await asyncio.to_thread(self.store.finish, iid, "faulted", None, reason)

    def busy_text(self) -> str:
        job = self.job
        if job is None:
            return "busy"
        if job.kind in ("inspection", "check") and job.inspection_id is not None and job.inspection_id.done() \
                and not job.inspection_id.cancelled() and job.inspection_id.exception() is None:
            what = "inspection" if job.kind == "inspection" else "a check on the master, inspection"
            return f"the station is running {what} {job.inspection_id.result()}; try again when it ends"
        return f"the station is busy ({job.kind}); try again when it ends"

    # ------------------------------------------------------------------ station commands
    async def command(self, name: str, who: str) -> dict:
        """pause, resume, stop, abort, reset, home; EngineStateError when the state
        does not allow it, Busy for reset/home while a job runs."""
        if name in ("pause", "resume", "stop", "abort"):
            await self.thread.run(self._engine_command, name, who)
        elif name in ("reset", "home"):
            if self.busy:
                raise Busy(self.busy_text())
            if name == "reset":
                try:
                    await self.thread.call(asyncio.wait_for(self.engine.reset(), timeout=self.settings.command_timeout_s))
                except PlanEnded as ended:
                    raise EngineStateError(ended.reason) from None
            else:
                await self.thread.run(self._check_can_home)
                self.start_job("home", self._home(), lambda fut: None)
        else:
            raise ValueError(f"unknown command {name!r}")
        with contextlib.suppress(StoreError):
            await asyncio.to_thread(self.store.log_event, "command", f"{name} by {who}")
        return self.station_status()

    def _engine_command(self, name: str, who: str) -> None:
        """On the station loop: the state check (the engine's own table) and the
        command, in one step."""
        engine = self.engine
        engine.check(name)
        if name == "abort":
            engine.abort(f"aborted by {who}")
        else:
            getattr(engine, name)()

    def _check_can_home(self) -> None:
        self.engine.check("home")

    async def _home(self) -> None:
        """On the station loop."""
        try:
            await asyncio.wait_for(self.engine.home(), timeout=self.engine.timeouts.home_s * 2)
        except (PlanEnded, asyncio.TimeoutError, EngineStateError) as exc:
            with contextlib.suppress(StoreError):
                await asyncio.to_thread(self.store.log_event, "alarm", f"homing failed: {exc}")

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
        monitor = self.monitor_state()
        return {"state": e.state.value, "reason": e.reason, "progress": {"done": done, "total": total, "text": text},
                "mode": self.station.mode, "busy": self.busy, "job": job,
                # "station needs a check" (docs/api.md): the station's charts asked for a check on the master
                "needs_check": monitor["needs_check"], "needs_check_reason": monitor["reason"], "monitor": monitor}
