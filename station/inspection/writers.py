"""The subscribers that record an inspection's documents (station.inspection.documents).

* :class:`StoreWriter` (required): the record. The start document begins it; the stop
  document commits the hole crops (each in a transaction of its own, just before),
  then every characteristic, the findings, the machine time, the surface document
  with its unrolled picture and the final state in one go, before the result is
  reported. When the store
  cannot take the result, the record is finished ``faulted`` with an alarm; when it
  takes nothing at all, the writer keeps the reason and closes the record at the next
  inspection it sees (or the next start of the store marks it ``interrupted``).
* :class:`EngineEventLog`: the engine's states, faults, retries and notes during the
  inspection, in the store's event log under the inspection's id.
* :class:`ScanLogWriter`: the grating's evidence of a complete inspection as a scan log
  (``station.inspection.scanlog``), after the commit: discovery reads it later, the
  result does not wait for it.
"""

from __future__ import annotations

import asyncio
import logging
import math
from datetime import datetime, timezone

from station.inspection.documents import CheckDocument, Document, InspectionStart, InspectionStop
from station.inspection.scanlog import write_scan_log
from station.store.errors import StoreError
from station.store.records import SURFACE_SUBJECT, FindingRecord, Measurement

log = logging.getLogger(__name__)


class ResultNotStored(Exception):
    """The store did not take an inspection's result; ``reason`` is what the record
    (when it could be finished at all) and the outcome say."""

    def __init__(self, inspection_id: str, reason: str):
        super().__init__(reason)
        self.inspection_id = inspection_id
        self.reason = reason


async def _alarm(store, inspection_id: str | None, text: str) -> None:
    """An alarm in the event log, written in a worker thread (never on the station loop)."""
    try:
        await asyncio.to_thread(store.log_event, "alarm", text, inspection_id)
    except Exception:  # noqa: BLE001 - the store is what failed; the outcome carries the reason
        pass


class StoreWriter:
    """The results store as a (required) subscriber. One per store and session: the
    records it could not finish are its own to close, not a module's."""

    def __init__(self, store):
        self.store = store
        #: inspection id -> the reason to finish it with once the store takes writes again
        self.unfinished: dict[str, str] = {}
        self._checks: dict[str, list[Measurement]] = {}

    async def __call__(self, doc: Document) -> None:
        if isinstance(doc, InspectionStart):
            await self._close_unfinished()
            await asyncio.to_thread(self.store.begin_inspection, doc.part_number, serial=doc.serial,
                                    order_id=doc.order_id, traceability=doc.traceability,
                                    idempotency_key=doc.idempotency_key, inspection_id=doc.inspection_id)
            self._checks[doc.inspection_id] = []
        elif isinstance(doc, CheckDocument) and doc.characteristic is not None:
            self._checks.setdefault(doc.inspection_id, []).append(doc.characteristic)
        elif isinstance(doc, InspectionStop) and doc.outcome is not None:
            await self._finish(doc)

    async def _finish(self, doc: InspectionStop) -> None:
        out = doc.outcome
        iid = doc.inspection_id
        if iid not in self._checks:
            # its stop was written (or failed and is kept in ``unfinished``): a second
            # stop, the one the service publishes after a failed commit, changes nothing
            return
        # the characteristics as their check documents carried them (with the truth, in
        # simulation, that the annotator wrote beside each before the stop)
        measurements = [Measurement(c.id, c.nominal, c.lower_limit, c.upper_limit, c.measured, c.passed,
                                    uncertainty_k2=c.uncertainty_k2, true_value=c.true_value)
                        for c in self._checks.pop(iid, [])]
        extra = cycle_fields(out.cycle)
        if out.state != "complete":
            await asyncio.to_thread(self.store.finish, iid, out.state, None, out.reason, **extra)
            return
        try:
            for r in doc.holes:
                if r.crop is not None and r.crop.size:
                    await asyncio.to_thread(self.store.add_image, iid, r.name, f"{r.name}", r.crop)
            await asyncio.to_thread(self.store.finish, iid, "complete", out.result, out.reason or None,
                                    measurements=measurements, findings=[FindingRecord.of(f) for f in out.findings],
                                    **extra, **surface_fields(out.surface))
        except (StoreError, ValueError, TypeError) as exc:
            # a store that fails, or a result it refuses (a surface document that is not
            # JSON, a picture that is not uint8): the record ends faulted, never running
            reason = f"result not stored: {type(exc).__name__}: {exc}"
            await _alarm(self.store, iid, reason)
            try:
                await asyncio.to_thread(self.store.finish, iid, "faulted", None, reason)
            except StoreError:
                self.unfinished[iid] = reason
            raise ResultNotStored(iid, reason) from exc

    async def _close_unfinished(self) -> None:
        """Records an earlier inspection could not finish because the store failed."""
        for iid, reason in sorted(self.unfinished.items()):
            try:
                await asyncio.to_thread(self.store.finish, iid, "faulted", None, reason)
                await _alarm(self.store, iid, "closed as faulted once the results store was back")
            except StoreError:
                continue
            self.unfinished.pop(iid, None)


def surface_fields(surface) -> dict:
    """The record's ``surface`` document and its picture (an image of the record,
    subject and name ``surface``) from a ``SurfaceResult``; nothing when the part spec
    asked for no surface inspection. The twin's truth of each defect is kept when the
    annotator gave one (simulation only), as a characteristic's ``true_value`` is."""
    if surface is None:
        return {}
    fields: dict = {"surface": surface.to_json(with_truth=True)}
    picture = surface.picture
    if picture is not None and picture.image is not None and picture.image.size:
        fields["images"] = [(SURFACE_SUBJECT, SURFACE_SUBJECT, picture.image)]
    return fields


def cycle_fields(cycle: dict | None) -> dict:
    """The record's ``machine_s`` and ``cycle`` from a cycle summary (nothing when the
    machine time is not a finite number)."""
    if cycle is None or not math.isfinite(cycle.get("machine_s", math.nan)):
        return {}
    return {"machine_s": cycle["machine_s"], "cycle": cycle}


class EngineEventLog:
    """The engine's events during an inspection, in the store's event log.

    The engine calls its listeners on the station loop, which also carries the drives'
    heartbeats; a store's commit (a PostgreSQL round trip, an SQLite fsync) on a loaded
    PC can take a second, the drives' watchdog. So an event is only queued there: its
    write runs in a worker thread, each after the one before (the log keeps the engine's
    order), with the time the event happened. :meth:`flush`, subscribed before the
    record's writer, waits at the inspection's stop until every queued event is in the
    log, so the record's end comes after its events, as when they were written at once.
    A write that fails is counted in ``failed`` and logged; it never stops the inspection.
    """

    KINDS = ("state", "fault", "retry", "note")
    #: how long the stop (and the session's end) waits for the queued events (s)
    FLUSH_TIMEOUT_S = 10.0

    def __init__(self, store, engine):
        self.store = store
        self.engine = engine
        self._unsubscribe = None
        #: the last queued write (each waits for the one before)
        self._tail: asyncio.Task | None = None
        #: writes the store refused
        self.failed = 0

    def __call__(self, doc: Document) -> None:
        if isinstance(doc, InspectionStart):
            self._stop()
            iid = doc.inspection_id
            self._unsubscribe = self.engine.subscribe(lambda ev: self._log(iid, ev))
        elif isinstance(doc, InspectionStop):
            self._stop()

    async def flush(self, doc: Document | None = None) -> None:
        """Wait until every queued event is in the log (at an inspection's stop, when
        given a document; always, without one), at most ``FLUSH_TIMEOUT_S``."""
        if doc is not None and not isinstance(doc, InspectionStop):
            return
        tail = self._tail
        if tail is None or tail.done():
            return
        done, _ = await asyncio.wait([tail], timeout=self.FLUSH_TIMEOUT_S)
        if not done:
            log.warning("the engine's events of the inspection were not all in the event log after %.0f s; "
                        "they are still being written", self.FLUSH_TIMEOUT_S)

    def _stop(self) -> None:
        if self._unsubscribe is not None:
            self._unsubscribe()
            self._unsubscribe = None

    def _log(self, iid: str, ev) -> None:
        if ev.kind not in self.KINDS:
            return
        text = f"{ev.state.value}: {ev.text}" if ev.kind == "state" else ev.text
        at = datetime.fromtimestamp(ev.time, timezone.utc)
        try:
            loop = asyncio.get_running_loop()
        except RuntimeError:
            # called outside a loop (no heartbeat to hold up): written at once
            self._write_now(ev.kind, text, iid, at)
            return
        self._tail = loop.create_task(self._write_after(self._tail, ev.kind, text, iid, at),
                                      name=f"event log {iid}")

    async def _write_after(self, before: asyncio.Task | None, kind: str, text: str, iid: str,
                           at: datetime) -> None:
        if before is not None and not before.done():
            await asyncio.wait([before])
        await asyncio.to_thread(self._write_now, kind, text, iid, at)

    def _write_now(self, kind: str, text: str, iid: str, at: datetime) -> None:
        try:
            self.store.log_event(kind, text, iid, at=at)
        except Exception as exc:  # noqa: BLE001 - the event log must not stop the inspection
            self.failed += 1
            log.warning("an engine event of inspection %s was not logged: %s: %s", iid, type(exc).__name__, exc)


class ScanLogWriter:
    """A complete inspection's grating readings as a scan log under the store's data folder."""

    def __init__(self, store):
        self.store = store

    async def __call__(self, doc: Document) -> None:
        if not isinstance(doc, InspectionStop) or doc.outcome is None or doc.outcome.state != "complete":
            return
        try:
            await asyncio.to_thread(write_scan_log, self.store.data_dir, doc.inspection_id, doc.holes)
        except OSError as exc:
            await _alarm(self.store, doc.inspection_id, f"scan log not written: {exc}")
