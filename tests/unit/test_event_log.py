"""The engine's event log writes off the station loop (station.inspection.writers.EngineEventLog).

The drives' heartbeats ride the station loop, and a drive faults its axis when none came
for its watchdog's second. A clean CI run lost a plant inspection that way: the loop was
inside an SQLAlchemy statement for 1.06 s on a loaded PC (session 59). The engine's
listeners are called on that loop, and the event log wrote each state change there. These
tests hold the store's write and check that the loop goes on, that the log keeps the
engine's order and times, and that the record's end is written after its events.
"""

from __future__ import annotations

import asyncio
import threading
import time
import uuid
from datetime import datetime, timedelta, timezone

import pytest

from station.inspection.documents import DocumentStream, InspectionStart, InspectionStop
from station.inspection.service import InspectionOutcome
from station.inspection.writers import EngineEventLog, StoreWriter
from station.sequencer.engine import EngineEvent, State
from station.store import Store

PART = "ZDZG-22.2-12.3851"


class _Engine:
    """The engine's listener interface, with events sent by the test."""

    def __init__(self) -> None:
        self.listeners = []

    def subscribe(self, fn):
        self.listeners.append(fn)
        return lambda: self.listeners.remove(fn)

    def emit(self, kind: str, state: State, text: str, t: float) -> None:
        for fn in list(self.listeners):
            fn(EngineEvent(t, kind, state, text))


class _HeldStore:
    """A store whose event writes wait until the test lets them go, and say which thread
    wrote them."""

    def __init__(self) -> None:
        self.release = threading.Event()
        self.written: list[tuple[str, str, str, datetime, int]] = []
        self.fail_next = False

    def log_event(self, kind, message, inspection_id=None, *, at=None):
        if not self.release.wait(timeout=10.0):
            raise TimeoutError("the test never released the store")
        if self.fail_next:
            self.fail_next = False
            raise RuntimeError("database is locked")
        self.written.append((kind, message, inspection_id, at, threading.get_ident()))


def test_the_engines_events_are_written_off_the_loop_in_order_with_their_times():
    store, engine = _HeldStore(), _Engine()
    elog = EngineEventLog(store, engine)
    iid = str(uuid.uuid4())
    t0 = time.time()

    async def go():
        loop_thread = threading.get_ident()
        elog(InspectionStart(iid, part_number=PART))
        engine.emit("state", State.RUNNING, "scan", t0)
        engine.emit("progress", State.RUNNING, "", t0 + 0.1)  # not a kind the log keeps
        engine.emit("note", State.RUNNING, "hole 1 found", t0 + 0.2)
        # the store holds every write; the loop still turns, many times over
        for _ in range(50):
            await asyncio.sleep(0)
        assert store.written == []
        engine.emit("retry", State.RUNNING, "C: timeout, again", t0 + 0.3)
        store.release.set()
        await elog.flush(InspectionStop(iid))
        return loop_thread

    loop_thread = asyncio.run(go())
    assert [(k, m) for k, m, *_ in store.written] == [("state", "running: scan"), ("note", "hole 1 found"),
                                                     ("retry", "C: timeout, again")]
    assert all(i == iid for _, _, i, _, _ in store.written)
    assert [at for *_, at, _ in store.written] == [datetime.fromtimestamp(t0 + d, timezone.utc)
                                                   for d in (0.0, 0.2, 0.3)]
    assert all(th != loop_thread for *_, th in store.written)


def test_a_write_the_store_refuses_is_counted_and_the_rest_go_on():
    store, engine = _HeldStore(), _Engine()
    elog = EngineEventLog(store, engine)
    iid = str(uuid.uuid4())
    store.fail_next = True
    store.release.set()

    async def go():
        elog(InspectionStart(iid, part_number=PART))
        engine.emit("state", State.RUNNING, "scan", time.time())
        engine.emit("fault", State.FAULTED, "Z: drive fault", time.time())
        await elog.flush()
        elog(InspectionStop(iid))
        engine.emit("note", State.IDLE, "after the stop", time.time())  # no longer listened to

    asyncio.run(go())
    assert elog.failed == 1
    assert [(k, m) for k, m, *_ in store.written] == [("fault", "Z: drive fault")]
    assert engine.listeners == []


def test_the_record_ends_after_its_engine_events_in_the_store(tmp_path):
    """Subscribed as the session does (the flush before the record's writer): the store's
    own final state event is the log's last entry of the inspection, and each engine event
    keeps the time it happened, however late its write."""
    engine = _Engine()
    iid = str(uuid.uuid4())
    with Store.open(data_dir=tmp_path / "data") as store:
        elog = EngineEventLog(store, engine)
        stream = DocumentStream()
        stream.subscribe(elog.flush)
        stream.subscribe(StoreWriter(store), required=True)
        stream.subscribe(elog)
        start = datetime.now(timezone.utc)
        times = [time.time() - 5.0 + k for k in range(4)]

        async def go():
            await stream.publish(InspectionStart(iid, part_number=PART, serial="SN-E"))
            for k, t in enumerate(times):
                engine.emit("state" if k % 2 == 0 else "note", State.RUNNING, f"step {k}", t)
            await stream.publish(InspectionStop(iid, outcome=InspectionOutcome(iid, PART, "SN-E", "aborted", None,
                                                                               "operator stop")))

        asyncio.run(go())
        events = store.events(iid)
        assert stream.errors == []
        assert [e.message for e in events[1:-1]] == ["running: step 0", "step 1", "running: step 2", "step 3"]
        assert events[0].message.startswith("running: part") and events[-1].message.startswith("aborted")
        assert [e.kind for e in events] == ["state", "state", "note", "state", "note", "state"]
        engine_events = events[1:-1]
        for e, t in zip(engine_events, times):
            assert abs((e.at - datetime.fromtimestamp(t, timezone.utc)).total_seconds()) < 1e-3
        assert events[-1].at >= start > engine_events[-1].at


def test_an_events_time_must_be_aware(tmp_path):
    with Store.open(data_dir=tmp_path / "data") as store:
        with pytest.raises(ValueError, match="aware datetime"):
            store.log_event("note", "when?", at=datetime(2026, 12, 3, 12, 0))
        rec = store.log_event("note", "then", at=datetime(2026, 12, 3, 12, 0, tzinfo=timezone(timedelta(hours=1))))
        assert rec.at == datetime(2026, 12, 3, 11, 0, tzinfo=timezone.utc)
