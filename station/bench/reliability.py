"""``station bench reliability``: the fault matrix, crash safety and fuzzing at full counts.

Three parts, shared with ``tests/reliability/`` (which run them at reduced counts):

* **fault matrix** -- every twin fault kind switched on when an inspection reaches a
  phase (homing, moving, settling, capturing, measuring, storing), on the device that
  phase uses; persistent (until the inspection's outcome) and, for the kinds the
  engine retries, transient (one call). Each cell records the outcome, the stored
  record, whether the axes stopped, and whether the *same session* inspects the next
  part correctly once the fault is cleared;
* **crash safety** -- a child process runs inspections back to back and is killed with
  SIGKILL after a random delay; after each kill the store is opened (recovery) and
  checked: every inspection complete and consistent or ``interrupted``, no reported
  inspection missing, ``PRAGMA integrity_check`` ok;
* **fuzzing** -- ``tests/reliability/test_fuzz.py``'s targets with many more examples
  (the targets live here so that the bench and the tests try the same thing).
"""

from __future__ import annotations

import asyncio
import contextlib
import dataclasses
import json
import os
import random
import signal
import subprocess
import sys
import tempfile
import textwrap
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

PART = "ZDZG-22.2-12.3851"
#: motion runs this much faster than real time in the matrix (timeouts stay real)
TIME_SCALE = 100.0

PHASES = ("homing", "moving", "settling", "capturing", "measuring", "storing")


def _kinds():
    from sim.faults import FaultKind

    return FaultKind


# ---------------------------------------------------------------------------- cells


@dataclass(frozen=True)
class Cell:
    """One cell of the matrix: a fault kind (a ``FaultKind`` value, or ``store_*`` /
    ``vision_error`` for the failures that are not a twin's), the phase where it is
    switched on, and whether it lasts for one call only (``transient``)."""

    kind: str
    phase: str
    transient: bool = False

    @property
    def id(self) -> str:
        return f"{self.kind}-{self.phase}" + ("-once" if self.transient else "")

    @property
    def device(self) -> str:
        """The twin the fault is switched on: "Z", "encoder" or "camera" (or "store", "vision")."""
        if self.kind.startswith("store"):
            return "store"
        if self.kind == "vision_error":
            return "vision"
        if self.kind in ("black_frame", "frozen_frame"):
            return "camera"
        if self.phase == "capturing" and self.kind in ("drop_connection", "delay"):
            return "camera"
        if self.phase == "measuring":
            return "encoder"
        return "Z"

    @property
    def expected(self) -> str:
        """What must happen: "complete" (the result is right despite the fault) or "faulted"."""
        if self.transient:
            return "complete"
        if self.phase == "storing":
            # a device fault after the scan does not touch the result; a store that
            # cannot commit ends the inspection faulted (the result is not reported)
            return "faulted" if self.device == "store" else "complete"
        return "faulted"


#: kinds the engine retries (the link, not the machine): they get a transient row too
TRANSIENT_KINDS = ("drop_connection", "delay", "garbage", "checksum", "black_frame", "frozen_frame")
DEVICE_KINDS = ("drop_connection", "delay", "garbage", "checksum", "stuck_axis", "drive_fault",
                "black_frame", "frozen_frame")


def matrix_cells() -> list[Cell]:
    cells = [Cell(k, p) for k in DEVICE_KINDS for p in PHASES]
    cells += [Cell(k, p, True) for k in TRANSIENT_KINDS for p in PHASES if p != "storing"]
    cells += [Cell("store_unavailable", "storing"), Cell("store_disk_full", "storing"),
              Cell("vision_error", "measuring")]
    return cells


#: a delay past each driver's timeout (Modbus 0.5 s, encoder 0.2 s, camera grab 1 s)
#: and one well inside it
LONG_DELAY_S = {"Z": 1.0, "encoder": 0.5, "camera": 1.5}
SHORT_DELAY_S = {"Z": 0.2, "encoder": 0.05, "camera": 0.3}


# ---------------------------------------------------------------------------- session in a thread


class SessionThread:
    """An inspection session living in an event loop of its own (a background thread),
    so that several tests (or bench cells) can share it: the point of the matrix is
    that the *same* session recovers. ``run(fn)`` runs ``await fn(session)`` there."""

    def __init__(self, data_dir: str | Path, *, time_scale: float = TIME_SCALE, frames_per_hole: int = 3,
                 small_frame: bool = True):
        self.data_dir = Path(data_dir)
        self.time_scale = time_scale
        self.frames_per_hole = frames_per_hole
        self.small_frame = small_frame
        self.session = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self._thread: threading.Thread | None = None
        self._closing: asyncio.Event | None = None
        self._ready = threading.Event()
        self._error: BaseException | None = None

    def start(self, timeout: float = 60.0) -> "SessionThread":
        self._thread = threading.Thread(target=lambda: asyncio.run(self._main()), name="session", daemon=True)
        self._thread.start()
        if not self._ready.wait(timeout):
            raise TimeoutError("the session did not open in time")
        if self._error is not None:
            raise self._error
        return self

    async def _main(self) -> None:
        from sim.camera.twin import small_optics
        from station.inspection.scan import ScanSettings
        from station.inspection.session import open_session

        self._loop = asyncio.get_running_loop()
        self._closing = asyncio.Event()
        try:
            async with open_session(time_scale=self.time_scale, data_dir=self.data_dir,
                                    settings=ScanSettings(frames_per_hole=self.frames_per_hole)) as s:
                if self.small_frame:
                    optics = small_optics()
                    s.station.camera.optics = optics
                    s.station.frame_size_px = (optics.params.width_px, optics.params.height_px)
                self.session = s
                self._ready.set()
                await self._closing.wait()
        except BaseException as exc:  # noqa: BLE001 - reported to start()
            self._error = exc
        finally:
            self._ready.set()

    def run(self, fn: Callable[[Any], Any], timeout: float = 120.0) -> Any:
        assert self._loop is not None and self.session is not None
        fut = asyncio.run_coroutine_threadsafe(fn(self.session), self._loop)
        try:
            return fut.result(timeout)
        except TimeoutError:
            fut.cancel()
            raise

    def close(self) -> None:
        if self._loop is not None and self._closing is not None and self._thread is not None and self._thread.is_alive():
            self._loop.call_soon_threadsafe(self._closing.set)
        if self._thread is not None:
            self._thread.join(timeout=30.0)
            self._thread = None

    def __enter__(self):
        return self.start()

    def __exit__(self, *exc):
        self.close()


# ---------------------------------------------------------------------------- injection


class _Proxy:
    """Delegates everything to ``target``; ``hooks[name]`` wraps the method ``name``."""

    def __init__(self, target, hooks: dict[str, Callable]):
        object.__setattr__(self, "_target", target)
        object.__setattr__(self, "_hooks", hooks)

    def __getattr__(self, name):
        attr = getattr(self._target, name)
        hook = self._hooks.get(name)
        return hook(attr) if hook is not None else attr


class Injector:
    """Switches ``cell``'s fault on when the inspection reaches its phase, on the twin
    the phase uses, and off again after one call (transient) or on ``clear()``."""

    def __init__(self, session, cell: Cell):
        self.s = session
        self.cell = cell
        self.fired = 0
        self.active = False
        self.calls_while_active = 0
        self._restore: list[Callable[[], None]] = []

    # -- the fault itself
    def _switch(self):
        from sim.faults import FaultKind

        twins = self.s.station.twins
        dev = self.cell.device
        if dev == "camera":
            return self.s.station.camera.faults, None
        if dev == "encoder":
            return twins.station.encoder.faults, twins
        return twins.station.drives[dev].faults, twins

    def fault_on(self) -> None:
        from sim.faults import FaultKind

        if self.active:
            return
        self.fired += 1
        self.active = True
        kind = self.cell.kind
        if kind == "vision_error":
            return
        switch, twins = self._switch()
        params: dict[str, Any] = {}
        if kind == "delay":
            params["delay_s"] = (SHORT_DELAY_S if self.cell.transient else LONG_DELAY_S)[self.cell.device]
        if kind == "drive_fault":
            params["code"] = 0x20
        fn = lambda: switch.activate(FaultKind(kind), **params)  # noqa: E731
        twins.call(fn) if twins is not None else fn()

    def fault_off(self) -> None:
        if not self.active:
            return
        self.active = False
        if self.cell.kind == "vision_error":
            return
        switch, twins = self._switch()
        twins.call(switch.clear) if twins is not None else switch.clear()

    # -- where the phase begins, and (transient) where it ends
    def _trigger(self, fn):
        """Wrap a method at which the phase begins: the fault goes on before its first call."""
        inj = self

        async def wrapped(*a, **k):
            if not inj.fired:
                inj.fault_on()
            return await fn(*a, **k)

        return wrapped

    def _target(self, fn):
        """Wrap a method of the faulted device: a transient fault goes off after the first
        call it met (that call sees the fault, the retry does not)."""
        inj = self

        async def wrapped(*a, **k):
            hit = inj.active
            if hit:
                inj.calls_while_active += 1
            try:
                return await fn(*a, **k)
            finally:
                if hit and inj.cell.transient:
                    inj.fault_off()

        return wrapped

    def _both(self, fn):
        return self._target(self._trigger(fn))

    def _vision(self, fn):
        inj = self

        def wrapped(*a, **k):
            if not inj.fired:
                inj.fault_on()
            if inj.active:
                inj.calls_while_active += 1
                raise RuntimeError("vision stage crashed (injected)")
            return fn(*a, **k)

        return wrapped

    def install(self) -> None:
        eng = self.s.engine
        d = eng.devices
        phase = self.cell.phase
        dev = self.cell.device
        attr_of = {"Z": "z", "encoder": "encoder", "camera": "camera"}
        target_methods = {"Z": ("enable", "home", "move_to", "wait_in_position", "status", "stop",
                                "read_position", "reset_fault"),
                          "encoder": ("read",), "camera": ("grab",)}
        if self.cell.kind == "vision_error":
            orig = d.measure
            d.measure = self._vision(orig)
            self._restore.append(lambda: setattr(d, "measure", orig))
            return
        trigger = {"homing": ("z", "home"), "moving": ("z", "move_to"), "capturing": ("camera", "grab"),
                   "measuring": ("encoder", "read")}.get(phase)
        hooks: dict[str, dict[str, Callable]] = {}
        if dev in attr_of:
            for name in target_methods[dev]:
                hooks.setdefault(attr_of[dev], {})[name] = self._target
        if trigger is not None:
            attr, name = trigger
            hooks.setdefault(attr, {})[name] = self._both if hooks.get(attr, {}).get(name) else self._trigger
        for attr, h in hooks.items():
            orig = getattr(d, attr)
            setattr(d, attr, _Proxy(orig, h))
            self._restore.append(lambda attr=attr, orig=orig: setattr(d, attr, orig))
        if phase == "settling":
            orig_sleep = eng._sleep
            eng._sleep = self._trigger(orig_sleep)
            self._restore.append(lambda: setattr(eng, "_sleep", orig_sleep))
        elif phase == "storing":
            self._install_store()

    def _install_store(self) -> None:
        store = self.s.store
        orig = store.finish
        cell = self

        def finish(*a, **k):
            first = not cell.fired
            if first and cell.cell.kind == "store_unavailable":
                cell.fired += 1
                from station.store import StoreUnavailable

                raise StoreUnavailable("results store: database is locked (injected: the commit failed once)")
            if first and cell.cell.kind == "store_disk_full":
                cell.fired += 1
                cell._fill_disk()
            elif first:
                cell.fault_on()
            return orig(*a, **k)

        store.finish = finish
        self._restore.append(lambda: store.__dict__.pop("finish", None))

    def _fill_disk(self) -> None:
        """The disk holding the database is full: from now on every INSERT INTO event (the
        last statement of ``finish``'s transaction, after its characteristics and the
        state change) fails as the database fails it, so the transaction must roll back
        whole: SQLite's "database or disk is full", PostgreSQL's "could not extend file
        ...: No space left on device" (SQLSTATE 53100), each raised as its own driver's
        exception. (SQLite's max_page_count cannot show this: the few rows of a finish
        fit in the free space of pages the database already has.)"""
        from sqlalchemy import event

        engine = self.s.store.engine
        if engine.dialect.name == "postgresql":
            import psycopg.errors

            def error():
                return psycopg.errors.DiskFull('could not extend file "base/16384/16390": No space left on device')
        else:
            import sqlite3

            def error():
                return sqlite3.OperationalError("database or disk is full")

        def full(conn, cursor, statement, parameters, context, executemany):
            if statement.lstrip().upper().startswith("INSERT INTO EVENT"):
                raise error()

        event.listen(engine, "before_cursor_execute", full)
        self.active = True
        self._restore.append(lambda: event.remove(engine, "before_cursor_execute", full))

    def clear(self) -> None:
        """The cause is gone: switch the fault off and take the wrappers away."""
        if self.cell.kind != "store_disk_full":
            self.fault_off()
        for undo in reversed(self._restore):
            undo()
        self._restore.clear()
        self.active = False


# ---------------------------------------------------------------------------- one cell


@dataclass
class CellResult:
    cell: Cell
    fired: bool = False
    state: str = ""
    result: str | None = None
    reason: str = ""
    engine_state: str = ""
    retries: int = 0
    stored_state: str = ""
    stored_reason: str = ""
    stored_chars: int = 0
    fault_events: int = 0
    alarm_events: int = 0
    axes_moving_after: bool = False
    max_error_mm: float = float("nan")
    next_state: str = ""
    next_result: str | None = None
    next_reason: str = ""
    next_max_error_mm: float = float("nan")
    wall_s: float = 0.0
    error: str = ""

    def problems(self) -> list[str]:
        """What is wrong with this cell's behaviour (empty: as specified)."""
        c, out = self.cell, []
        if self.error:
            out.append(f"raised {self.error}")
            return out
        if not self.fired:
            out.append("the fault was never switched on (phase not reached)")
        exp = c.expected
        if self.state != exp:
            out.append(f"ended {self.state!r} ({self.reason}), expected {exp!r}")
        if exp == "complete":
            if self.result != "pass":
                out.append(f"result {self.result!r}, expected pass ({self.reason})")
            if not self.max_error_mm <= 3e-3:
                out.append(f"measured {self.max_error_mm * 1e3:.1f} um from the truth")
        if exp == "faulted":
            if not self.reason:
                out.append("no reason given")
            if self.stored_state != "faulted" or self.stored_reason != self.reason:
                out.append(f"stored as {self.stored_state!r} ({self.stored_reason!r})")
            if c.device != "store" and self.fault_events < 1:
                out.append("no fault event logged")
            if c.device == "store" and self.alarm_events < 1:
                out.append("no alarm logged")
            if c.device == "store" and self.stored_chars:
                out.append(f"half-written: {self.stored_chars} characteristics stored for a result not stored")
        elif self.stored_state != "complete" or self.stored_chars != 4:
            out.append(f"stored as {self.stored_state!r} with {self.stored_chars} characteristics")
        if self.axes_moving_after:
            out.append("an axis was still moving after the outcome")
        if self.next_state != "complete" or self.next_result != "pass" or not self.next_max_error_mm <= 3e-3:
            out.append(f"next inspection: {self.next_state} {self.next_result} ({self.next_reason})")
        return out

    def to_json(self) -> dict:
        d = dataclasses.asdict(self)
        d["cell"] = self.cell.id
        d["problems"] = self.problems()
        return d


def _max_error(out) -> float:
    errs = [abs(c.measured - c.true_value) for c in out.characteristics
            if c.measured is not None and c.true_value is not None]
    return max(errs) if len(errs) == len(out.characteristics) and errs else float("nan")


async def run_cell(s, spec, cell: Cell, serial: str = "SN-CELL") -> CellResult:
    """Run one inspection with ``cell``'s fault, clear it, run the next one; observe everything."""
    from station.sequencer.engine import State

    res = CellResult(cell)
    t0 = time.perf_counter()
    if cell.phase == "homing" and s.engine.state == State.READY:
        await s.engine.reset()  # the next inspection homes first
    inj = Injector(s, cell)
    retries: list[str] = []
    count = lambda ev: retries.append(ev.text) if ev.kind == "retry" else None  # noqa: E731
    s.engine.subscribe(count)
    inj.install()
    try:
        try:
            out = await asyncio.wait_for(s.inspect(spec, serial), 90.0)
        except Exception as exc:  # noqa: BLE001 - the cell reports it
            res.error = f"{type(exc).__name__}: {exc}"
            return res
        res.fired = inj.fired > 0
        res.state, res.result, res.reason = out.state, out.result, out.reason
        res.engine_state = s.engine.state.value
        res.retries = len(retries)  # homing's included (retries_used counts a plan's only)
        res.max_error_mm = _max_error(out)
        twins = s.station.twins
        res.axes_moving_after = any(
            twins.call(lambda n=n: twins.station.physics[n].snapshot().moving) for n in ("Z", "C"))
    finally:
        inj.clear()
        s.engine._listeners.remove(count)
    try:
        nxt = await asyncio.wait_for(s.inspect(spec, serial + "-NEXT"), 90.0)
        res.next_state, res.next_result, res.next_reason = nxt.state, nxt.result, nxt.reason
        res.next_max_error_mm = _max_error(nxt)
        nrec = await asyncio.to_thread(s.store.get, nxt.id)
        if nrec.state != nxt.state:
            res.next_state = f"{nxt.state} (stored {nrec.state})"
    except Exception as exc:  # noqa: BLE001
        res.next_state, res.next_reason = "raised", f"{type(exc).__name__}: {exc}"
    # the faulted inspection's record, as it stands once the station is running again
    rec = await asyncio.to_thread(s.store.get, out.id)
    res.stored_state, res.stored_reason, res.stored_chars = rec.state, rec.reason or "", len(rec.characteristics)
    events = await asyncio.to_thread(s.store.events, out.id, limit=1000)
    res.fault_events = sum(1 for e in events if e.kind == "fault")
    res.alarm_events = sum(1 for e in events if e.kind == "alarm")
    res.wall_s = time.perf_counter() - t0
    return res


# ---------------------------------------------------------------------------- crash safety

#: the child: inspections back to back; an id is printed only after ``inspect`` returned,
#: i.e. after the commit -- every printed id is an acknowledged result
CRASH_CHILD = textwrap.dedent(
    """
    import asyncio, sys
    from sim.camera.twin import small_optics
    from station.inspection.scan import ScanSettings
    from station.inspection.session import open_session
    from station.parts import load_part

    async def main(data, n, prefix, url):
        spec = load_part(%r)
        async with open_session(time_scale=%r, data_dir=data, db_url=url,
                                settings=ScanSettings(frames_per_hole=3)) as s:
            optics = small_optics()
            s.station.camera.optics = optics
            s.station.frame_size_px = (optics.params.width_px, optics.params.height_px)
            print("ready", flush=True)
            for i in range(n):
                out = await s.inspect(spec, f"{prefix}-{i:02d}")
                print("done", out.id, out.state, out.result, flush=True)

    asyncio.run(main(sys.argv[1], int(sys.argv[2]), sys.argv[3], sys.argv[4] if len(sys.argv) > 4 else None))
    """
) % (PART, TIME_SCALE)


@dataclass
class CrashReport:
    kills: int = 0
    acknowledged: int = 0
    inspections: int = 0
    complete: int = 0
    interrupted: int = 0
    faulted: int = 0
    #: acknowledged ids not found complete in the store (goal: none)
    lost: list[str] = field(default_factory=list)
    #: anything else wrong: inconsistent results, running rows after recovery, integrity
    problems: list[str] = field(default_factory=list)
    delays_s: list[float] = field(default_factory=list)

    def to_json(self) -> dict:
        return dataclasses.asdict(self)


def check_store(data_dir: Path, acknowledged: dict[str, str],
                db_url: str | None = None) -> tuple[dict[str, int], list[str], list[str]]:
    """Open the store as the station does (recovery), check every record; returns counts,
    lost acknowledged ids and problems."""
    from station.store import Store

    problems: list[str] = []
    counts = {"inspections": 0, "complete": 0, "interrupted": 0, "faulted": 0}
    store = Store.open(db_url, data_dir=data_dir)
    try:
        if store.engine.dialect.name == "sqlite":  # a server database is the server's to keep sound
            with store.engine.connect() as conn:
                ok = conn.exec_driver_sql("PRAGMA integrity_check").scalar()
                if ok != "ok":
                    problems.append(f"integrity_check: {ok}")
        total = store.count_inspections()
        summaries = store.list_inspections(limit=max(total, 1))
        counts["inspections"] = len(summaries)
        for summ in summaries:
            rec = store.get(summ.id)
            counts[rec.state] = counts.get(rec.state, 0) + 1
            if rec.state == "running":
                problems.append(f"{rec.id} still running after recovery")
            elif rec.state == "complete":
                chars = rec.characteristics
                if len(chars) != 4:
                    problems.append(f"{rec.id} complete with {len(chars)} characteristics")
                passed = all(c.passed for c in chars)
                if (rec.result == "pass") != passed:
                    problems.append(f"{rec.id} result {rec.result} but characteristics passed={passed}")
                for c in chars:
                    if c.measured is None or c.true_value is None or abs(c.measured - c.true_value) > 3e-3:
                        problems.append(f"{rec.id} {c.characteristic_id}: {c.measured} vs truth {c.true_value}")
            elif rec.state == "interrupted" and not rec.reason:
                problems.append(f"{rec.id} interrupted without a reason")
        lost = []
        for iid, state in acknowledged.items():
            try:
                rec = store.get(iid)
            except Exception:  # noqa: BLE001 - InspectionNotFound: lost
                lost.append(iid)
                continue
            if rec.state != state:
                lost.append(iid)
                problems.append(f"acknowledged {iid} as {state}, stored {rec.state}")
    finally:
        store.close()
    return counts, lost, problems


#: longest a crash-test child may take to say it is ready (a loaded two-core PC)
READY_TIMEOUT_S = 120.0


def crash_trials(n: int, data_dir: str | Path, *, seed: int = 0, max_delay_s: float = 6.0,
                 per_child: int = 20, log: Callable[[str], None] | None = None,
                 db_url: str | None = None) -> CrashReport:
    """``n`` times: start the child, SIGKILL it after a random delay, recover and check
    (``db_url``: the database, default SQLite in ``data_dir``).

    One kill in four lands in the child's start-up (0.3-3 s after it was started: imports,
    the store's migration and recovery, the twins); the others a random 0.3 s to
    ``max_delay_s`` after the child said it was ready, among its homing, scans and
    commits. Timed from "ready", the kills hit inspections however long a loaded
    machine takes to start a Python process."""
    rng = random.Random(seed)
    data_dir = Path(data_dir)
    rep = CrashReport()
    acknowledged: dict[str, str] = {}
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    for trial in range(n):
        in_startup = rng.random() < 0.25
        delay = rng.uniform(0.3, 3.0) if in_startup else rng.uniform(0.3, max_delay_s)
        args = [str(data_dir), str(per_child), f"K{trial:03d}"] + ([db_url] if db_url else [])
        proc = subprocess.Popen([sys.executable, "-c", CRASH_CHILD, *args],
                                stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True, env=env)
        lines: list[str] = []
        ready = threading.Event()

        def read(proc=proc, lines=lines, ready=ready):
            for line in iter(proc.stdout.readline, ""):
                lines.append(line)
                if line.startswith("ready"):
                    ready.set()
            ready.set()  # the child ended (or was killed): nobody waits for a ready that never comes

        reader = threading.Thread(target=read, daemon=True)
        reader.start()
        try:
            if not in_startup:
                ready.wait(timeout=READY_TIMEOUT_S)
            try:
                proc.wait(timeout=delay)
            except subprocess.TimeoutExpired:
                os.kill(proc.pid, signal.SIGKILL)
            proc.wait(timeout=30)
        finally:
            if proc.poll() is None:
                proc.kill()
                proc.wait()
        reader.join(timeout=10)
        proc.stdout.close()
        rep.kills += 1
        rep.delays_s.append(round(delay, 3))
        for line in lines:
            parts = line.split()
            if len(parts) >= 3 and parts[0] == "done":
                acknowledged[parts[1]] = parts[2]
        counts, lost, problems = check_store(data_dir, acknowledged, db_url)
        rep.lost = lost
        rep.problems += [f"kill {trial}: {p}" for p in problems]
        if log is not None:
            log(f"kill {trial + 1}/{n} after {delay:.2f} s: {len(acknowledged)} acknowledged, {counts}")
    rep.acknowledged = len(acknowledged)
    rep.inspections = counts["inspections"]
    rep.complete = counts.get("complete", 0)
    rep.interrupted = counts.get("interrupted", 0)
    rep.faulted = counts.get("faulted", 0)
    return rep


# ---------------------------------------------------------------------------- fuzzing

RECORDING_SEED = """# axis: Z
# kind: linear
time_s,run,direction,target,deviation,temperature_c,note
0.0,1,+1,0.0,0.1,20.0,a
1.0,1,+1,60.0,3.2,20.1,b
2.0,1,-1,60.0,1.1,20.2,
3.0,1,-1,0.0,-0.9,20.3,c
"""

AXIS_MODEL_SEED = """[axis]
name = "Z"
kind = "linear"

[baseline]
target = [0.0, 60.0, 120.0]
deviation = [0.0, 6.0, 18.0]

[noise]
sigma = 0.5

[[effects]]
name = "backlash"
reversal = 4.0
"""

#: tokens a mutation puts where a value was: the awkward cases of every text format
NASTY = ("", " ", "nan", "inf", "-inf", "1e999", "-0", "0x10", "1,5", "+", "-", "\"", "'", "[", "]", "{", "}",
         "=", "#", "\n", "\r\n", "\x00", "\ufeff", "é", "9" * 40, "-1", "0", "1e-320", "true", "[[x]]", ",,,")


@dataclass
class FuzzTarget:
    """One parser under fuzzing: valid seed texts to mutate, the call, and the typed
    errors its documentation allows (anything else is a crash)."""

    name: str
    seeds: Callable[[], list]
    call: Callable[[Any], Any]
    errors: tuple[type[BaseException], ...]
    binary: bool = False


def _table_seeds() -> list[str]:
    import numpy as np

    from station.compensation import files as f
    from station.compensation.table import CompensationTable

    pos = np.array([0.0, 30.0, 60.0, 90.0, 120.0])
    uni = CompensationTable(kind="linear", position=pos, error_mean=np.array([0.0, 1.5, 3.0, 2.0, -1.0]), axis="Z")
    bi = CompensationTable(kind="rotary", position=pos * 3, error_up=np.array([0.0, 1.0, 2.0, 1.0, 0.0]),
                           error_down=np.array([0.5, 1.5, 2.5, 1.5, 0.5]), axis="C")
    return [f.table_to_csv(uni), f.table_to_csv(bi), f.table_to_json(uni), f.table_to_json(bi),
            f.table_to_linuxcnc(uni, 0), f.table_to_linuxcnc(bi, 1)]


def _segment_seeds() -> list[str]:
    from station.compensation import files as f
    from station.compensation.segments import Segment, SegmentModel

    m = SegmentModel(segments=(Segment(0.0, 60.0, 0.05, 0.0), Segment(60.0, 120.0, -0.02, 4.2)))
    return [f.segments_to_csv(m), f.segments_to_json(m)]


def _model_seeds() -> list[str]:
    from importlib import resources

    return [resources.files("station").joinpath("data/default_station.toml").read_text(),
            (Path(__file__).resolve().parents[2] / "sim" / "scenarios" / "paper_model.toml").read_text()
            if (Path(__file__).resolve().parents[2] / "sim" / "scenarios" / "paper_model.toml").is_file() else ""]


def _part_seeds() -> list[str]:
    from importlib import resources

    return [resources.files("station").joinpath(f"data/parts/{PART}.toml").read_text()]


def _model_call(text: str):
    import tomllib

    from station.kinematics.model import model_from_dict

    return model_from_dict(tomllib.loads(text), "<fuzz>")


def _axis_model_call(text: str):
    import tomllib

    from station.axis_model import axis_model_from_dict

    return axis_model_from_dict(tomllib.loads(text), "<fuzz>")


def _linuxcnc_call(text: str):
    from station.compensation.files import table_from_linuxcnc

    return table_from_linuxcnc(text, None, source="<fuzz>")


def _encoder_seeds() -> list[bytes]:
    from drivers.interfaces import encoder_protocol as ep

    return [ep.position_reply(842469, 1), ep.position_reply(-1234, 3), ep.identity_reply("GRT-005", "V1.3"),
            ep.error_reply(ep.EncoderErrorCode.UNKNOWN_COMMAND), b"\x00\xffnoise" + ep.position_reply(5, 1)]


def _find_frame_call(data: bytes):
    from drivers.encoder import find_frame

    return find_frame(data.rstrip(b"\r\n"))


class _ByteTransport:
    """A serial port that answers every query with the given bytes (in chunks)."""

    def __init__(self, data: bytes):
        self.data = data
        self.buf = b""

    def write(self, q):
        self.buf += self.data
        return len(q)

    def read(self, size=1):
        out, self.buf = self.buf[:size], self.buf[size:]
        return out

    @property
    def in_waiting(self):
        return len(self.buf)

    def reset_input_buffer(self):
        self.buf = b""

    def close(self):
        pass


def _encoder_driver_call(data: bytes):
    from drivers.encoder import SerialGratingEncoder

    enc = SerialGratingEncoder(transport=_ByteTransport(data), timeout_s=0.01, retries=0)
    return asyncio.run(enc.read())


class _FakeResponse:
    def __init__(self, registers, error):
        self.registers = registers
        self._error = error
        self.exception_code = 2

    def isError(self):
        return self._error


class _FakeModbusClient:
    """pymodbus' client face, answering from a script: register lists of any length and
    value, error responses, pymodbus exceptions, None."""

    def __init__(self, script: list):
        self.script = list(script)
        self.connected = True

    async def connect(self):
        return True

    def close(self):
        pass

    def _next(self, count):
        from pymodbus.exceptions import ConnectionException, ModbusIOException

        item = self.script.pop(0) if self.script else ("regs", [0] * count)
        kind, value = item
        if kind == "regs":
            return _FakeResponse(value, False)
        if kind == "error":
            return _FakeResponse([], True)
        if kind == "none":
            return None
        if kind == "io":
            raise ModbusIOException(str(value))
        raise ConnectionException(str(value))

    async def read_holding_registers(self, address, count=1, device_id=1):
        return self._next(count)

    async def write_registers(self, address, values, device_id=1):
        return self._next(0)


def _modbus_call(script: list):
    from drivers.modbus_axis import ModbusLinearAxis

    async def go():
        client = _FakeModbusClient(script)
        ax = ModbusLinearAxis(lambda: client, name="Z", device_id=1, unit_per_count=1e-4, default_velocity=20.0,
                              default_acceleration=200.0, timeout_s=0.05, watchdog_timeout_ms=0)
        try:
            await ax.status()
            await ax.read_position()
            await ax.move_to(1.0)
            await ax.wait_in_position(timeout=0.05, poll_s=0.001)
        finally:
            await ax.close()

    return asyncio.run(go())


def fuzz_targets() -> list[FuzzTarget]:
    import tomllib

    from drivers.interfaces import DriverError
    from drivers.interfaces import encoder_protocol as ep
    from station.axis_model import AxisModelError
    from station.compensation import files as f
    from station.kinematics.model import ModelConfigError
    from station.kinematics.topology import TopologyError
    from station.parts.loader import PartSpecError, parse_part
    from station.recording import RecordingError, parse_recording

    return [
        FuzzTarget("recording", lambda: [RECORDING_SEED], lambda t: parse_recording(t, "<fuzz>"), (RecordingError,)),
        FuzzTarget("compensation table csv", lambda: _table_seeds()[:2], lambda t: f.table_from_csv(t, "<fuzz>"),
                   (f.FormatError,)),
        FuzzTarget("compensation segments csv", lambda: _segment_seeds()[:1],
                   lambda t: f.segments_from_csv(t, "<fuzz>"), (f.FormatError,)),
        FuzzTarget("compensation json", lambda: _table_seeds()[2:4] + _segment_seeds()[1:],
                   lambda t: f.from_json(t, "<fuzz>"), (f.FormatError,)),
        FuzzTarget("compensation linuxcnc", lambda: _table_seeds()[4:], _linuxcnc_call, (f.FormatError,)),
        FuzzTarget("part spec", _part_seeds, lambda t: parse_part(t, "<fuzz>"), (PartSpecError,)),
        FuzzTarget("axis model toml", lambda: [AXIS_MODEL_SEED], _axis_model_call,
                   (tomllib.TOMLDecodeError, AxisModelError)),
        FuzzTarget("station model toml", lambda: [t for t in _model_seeds() if t], _model_call,
                   (tomllib.TOMLDecodeError, ModelConfigError, TopologyError)),
        FuzzTarget("encoder find_frame", _encoder_seeds, _find_frame_call, (ep.FrameError,), binary=True),
        FuzzTarget("encoder driver", _encoder_seeds, _encoder_driver_call, (DriverError,), binary=True),
    ]


def modbus_target():
    from drivers.interfaces import DriverError

    return FuzzTarget("modbus responses", lambda: [], _modbus_call, (DriverError,))


def mutated_text(seed, binary: bool = False):
    """A hypothesis strategy: ``seed`` with random edits (cuts, inserts of random or nasty
    text, swapped lines, replaced characters), or entirely random text now and then."""
    from hypothesis import strategies as hs

    alphabet = hs.binary(max_size=30) if binary else hs.text(max_size=30)
    nasty = hs.sampled_from([n.encode("utf-8") for n in NASTY] if binary else list(NASTY))
    edit = hs.tuples(hs.sampled_from(["cut", "insert", "nasty", "dup", "swap"]), hs.floats(0, 1), hs.floats(0, 1),
                     hs.one_of(alphabet, nasty))

    def apply(edits):
        t = seed
        for op, a, b, piece in edits:
            n = len(t)
            i, j = sorted((int(a * n), int(b * n)))
            if op == "cut":
                t = t[:i] + t[j:]
            elif op == "insert":
                t = t[:i] + piece + t[i:]
            elif op == "nasty":
                t = t[:i] + piece + t[j if j - i < 12 else i + 1:]
            elif op == "dup":
                t = t[:j] + t[i:j] + t[j:]
            else:
                t = t[i:j] + t[:i] + t[j:]
        return t

    return hs.one_of(hs.lists(edit, min_size=1, max_size=6).map(apply), alphabet)


def modbus_scripts():
    from hypothesis import strategies as hs

    regs = hs.lists(hs.integers(0, 0xFFFF), max_size=10)
    item = hs.one_of(hs.tuples(hs.just("regs"), regs), hs.tuples(hs.just("error"), hs.none()),
                     hs.tuples(hs.just("none"), hs.none()), hs.tuples(hs.just("io"), hs.text(max_size=20)),
                     hs.tuples(hs.just("lost"), hs.text(max_size=20)))
    return hs.lists(item, max_size=12)


class Hang(Exception):
    """The call under fuzzing did not return within its time limit."""


@contextlib.contextmanager
def time_limit(seconds: float):
    """SIGALRM-bounded block (main thread only): a parser that loops raises :class:`Hang`."""
    def on_alarm(_sig, _frame):
        raise Hang(f"no answer within {seconds} s")

    old = signal.signal(signal.SIGALRM, on_alarm)
    signal.setitimer(signal.ITIMER_REAL, seconds)
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, old)


def fuzz_one(target: FuzzTarget, value, limit_s: float = 5.0) -> str | None:
    """Run one input: None when it parsed or failed with a documented error (which must
    carry a message), else what went wrong."""
    try:
        with time_limit(limit_s):
            target.call(value)
    except target.errors as exc:
        if not str(exc).strip():
            return f"{type(exc).__name__} without a message for {value!r:.200}"
        return None
    except Hang as exc:
        return f"hang: {exc} for {value!r:.200}"
    except Exception as exc:  # noqa: BLE001 - that is what fuzzing looks for
        return f"{type(exc).__name__}: {exc} for {value!r:.200}"
    return None


def run_fuzz(max_examples: int, seed: int = 0) -> dict[str, dict]:
    """Every target with ``max_examples`` per seed text; inputs tried and failures per target."""
    from hypothesis import HealthCheck, given, settings, seed as hseed

    out: dict[str, dict] = {}
    targets = fuzz_targets() + [modbus_target()]
    for target in targets:
        tried, failures = [0], []
        strategies = [modbus_scripts()] if target.name == "modbus responses" else [
            mutated_text(sd, target.binary) for sd in target.seeds()]
        for strat in strategies:
            @hseed(seed)
            @settings(max_examples=max_examples, deadline=None, database=None,
                      suppress_health_check=list(HealthCheck))
            @given(strat)
            def one(value):
                tried[0] += 1
                problem = fuzz_one(target, value)
                if problem and len(failures) < 20:
                    failures.append(problem)

            one()
        out[target.name] = {"inputs": tried[0], "failures": failures}
    return out


# ---------------------------------------------------------------------------- command


def run_matrix(repeats: int = 1, log: Callable[[str], None] | None = None, only: str = "") -> list[CellResult]:
    """Every cell ``repeats`` times, one session per fault kind (shared by its cells)."""
    from station.parts import load_part

    spec = load_part(PART)
    cells = sorted((c for c in matrix_cells() if only in c.id), key=lambda c: (c.kind, c.transient))
    results: list[CellResult] = []
    with tempfile.TemporaryDirectory(prefix="matrix-") as root:
        kind, st = None, None
        try:
            for cell in cells:
                if cell.kind != kind:
                    if st is not None:
                        st.close()
                    st, kind = SessionThread(Path(root) / cell.kind).start(), cell.kind
                for k in range(repeats):
                    try:
                        r = st.run(lambda s: run_cell(s, spec, cell, serial=f"SN-{cell.id}-{k}"), timeout=240)
                    except Exception as exc:  # noqa: BLE001 - reported as the cell's error
                        r = CellResult(cell, error=f"{type(exc).__name__}: {exc}")
                    results.append(r)
                    if log is not None:
                        probs = r.problems()
                        log(f"{cell.id:32s} {r.state or '-':9s} {'ok' if not probs else 'PROBLEM: ' + '; '.join(probs)}")
        finally:
            if st is not None:
                st.close()
    return results


def register(app) -> None:
    import typer

    from station.cli.common import err_console, out_console, print_json

    @app.command("reliability")
    def reliability(
        json_out: bool = typer.Option(False, "--json", help="one JSON document"),
        repeats: int = typer.Option(1, help="runs of each fault-matrix cell"),
        kills: int = typer.Option(50, help="SIGKILLs of the inspecting process"),
        examples: int = typer.Option(1000, help="fuzz examples per seed text"),
        parts: str = typer.Option("matrix,crash,fuzz", help="which parts to run"),
    ):
        """Fault matrix, crash safety (SIGKILL) and fuzzing at full counts."""
        wanted = {p.strip() for p in parts.split(",")}
        say = (lambda msg: err_console.print(msg, markup=False, highlight=False))
        doc: dict[str, Any] = {}
        bad = False
        if "matrix" in wanted:
            t0 = time.perf_counter()
            res = run_matrix(repeats, log=say)
            rows = [r.to_json() for r in res]
            bad |= any(r["problems"] for r in rows)
            doc["matrix"] = {"cells": len({r["cell"] for r in rows}), "runs": len(rows),
                             "with_problems": sorted({r["cell"] for r in rows if r["problems"]}),
                             "wall_s": round(time.perf_counter() - t0, 1),
                             "results": [{k: r[k] for k in ("cell", "state", "result", "reason", "retries",
                                                            "next_state", "next_result", "problems")} for r in rows]}
        if "crash" in wanted:
            t0 = time.perf_counter()
            with tempfile.TemporaryDirectory(prefix="crash-") as d:
                rep = crash_trials(kills, d, seed=2024, log=say)
            bad |= bool(rep.lost or rep.problems)
            doc["crash"] = {**rep.to_json(), "records_lost": len(rep.lost), "wall_s": round(time.perf_counter() - t0, 1)}
        if "fuzz" in wanted:
            t0 = time.perf_counter()
            fz = run_fuzz(examples)
            bad |= any(v["failures"] for v in fz.values())
            doc["fuzz"] = {"targets": fz, "inputs": sum(v["inputs"] for v in fz.values()),
                           "wall_s": round(time.perf_counter() - t0, 1)}
        if json_out:
            print_json(doc)
        else:
            if "matrix" in doc:
                m = doc["matrix"]
                out_console.print(f"fault matrix: {m['cells']} cells, {m['runs']} runs, "
                                  f"{len(m['with_problems'])} with problems {m['with_problems']}  ({m['wall_s']} s)")
            if "crash" in doc:
                c = doc["crash"]
                out_console.print(f"crash: {c['kills']} kills, {c['acknowledged']} acknowledged, {c['inspections']} "
                                  f"inspections ({c['complete']} complete, {c['interrupted']} interrupted, "
                                  f"{c['faulted']} faulted), records lost {c['records_lost']}, "
                                  f"problems {len(c['problems'])}  ({c['wall_s']} s)")
            if "fuzz" in doc:
                for name, v in doc["fuzz"]["targets"].items():
                    out_console.print(f"fuzz {name}: {v['inputs']} inputs, {len(v['failures'])} failures")
        raise typer.Exit(1 if bad else 0)
