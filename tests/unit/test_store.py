"""Results store: round trip, filters and paging, idempotency, final results, crash
recovery with a killed process, migrations equal to the models, and the typed
errors of a locked or full database."""

from __future__ import annotations

import hashlib
import json
import os
import signal
import sqlite3
import subprocess
import sys
import textwrap
import time
from datetime import datetime, timedelta, timezone
from pathlib import Path

import cv2
import numpy as np
import pytest
from alembic import command
from alembic.autogenerate import compare_metadata
from alembic.runtime.migration import MigrationContext
from sqlalchemy import event, inspect, select
from typer.testing import CliRunner

from station.cli import app
from station.parts import load_part
from station.store import (
    FindingRecord,
    DuplicateIdempotencyKey,
    InspectionNotFound,
    InspectionStateError,
    Measurement,
    Store,
    StoreError,
    StoreIntegrityError,
    StoreLocked,
    StoreUnavailable,
    Traceability,
    upgrade_to_head,
)
from station.store.engine import _set_wal, make_engine
from station.store.migrate import alembic_config, current_revision, head_revision
from station.store.models import Base, Event

REPO = Path(__file__).resolve().parents[2]
PART = "ZDZG-22.2-12.3851"
T0 = datetime(2025, 3, 1, 8, 0, tzinfo=timezone.utc)


@pytest.fixture
def spec():
    return load_part(PART)


@pytest.fixture
def store(tmp_path):
    s = Store.open(data_dir=tmp_path / "data")
    yield s
    s.close()


def _m(spec, cid: str, value: float | None, **kw) -> Measurement:
    c = spec.characteristic(cid)
    passed = kw.pop("passed", value is not None and c.conforms(value))
    return Measurement.of(c, value, passed=passed, **kw)


def test_round_trip_with_characteristics_and_image(store, spec):
    trace = Traceability(model_version="m-3", compensation_version="c-7", calibration_id="cal-2025-02",
                         config_hash="abc123", scenario="default", extra={"operator": "shift-b"})
    iid = store.begin_inspection(PART, serial="SN-1", order_id="PO-9", traceability=trace, idempotency_key="mes-1")
    store.record_characteristic(iid, _m(spec, "hole_1.diameter", 0.675, uncertainty_k2=0.004, true_value=0.7))
    crop = np.arange(24 * 32, dtype=np.uint8).reshape(24, 32)
    image = store.add_image(iid, "hole_1", "hole_1_diameter", crop)
    done = store.finish(iid, "complete", "fail", "hole_2 position out of tolerance", measurements=[
        _m(spec, "hole_1.position", 71.130), _m(spec, "hole_2.diameter", 0.708), _m(spec, "hole_2.position", 85.080),
    ])

    again = store.get(iid)
    assert again == done
    assert (again.part_number, again.serial, again.order_id) == (PART, "SN-1", "PO-9")
    assert (again.state, again.result, again.reason) == ("complete", "fail", "hole_2 position out of tolerance")
    assert again.idempotency_key == "mes-1"
    assert again.traceability == trace.to_json()
    assert again.started_at.tzinfo is timezone.utc and again.finished_at >= again.started_at
    assert [c.characteristic_id for c in again.characteristics] == [c.id for c in spec.characteristics()]
    d1 = again.characteristic("hole_1.diameter")
    assert (d1.measured, d1.uncertainty_k2, d1.true_value, d1.passed, d1.unit) == (0.675, 0.004, 0.7, True, "mm")
    assert (d1.lower_limit, d1.upper_limit, d1.nominal) == (0.575, 0.825, 0.7)
    assert again.characteristic("hole_1.position").passed  # on the limit: inside (Table 4)
    assert not again.characteristic("hole_2.position").passed

    (img,) = again.images
    assert img == image and img.subject == "hole_1"
    assert img.path == f"images/{iid}/hole_1_diameter.png"
    on_disk = store.image_path(img)
    assert on_disk == store.data_dir / "images" / iid / "hole_1_diameter.png"
    assert hashlib.sha256(on_disk.read_bytes()).hexdigest() == img.sha256
    np.testing.assert_array_equal(cv2.imread(str(on_disk), cv2.IMREAD_UNCHANGED), crop)
    assert not [p for p in on_disk.parent.iterdir() if p.name.startswith(".")]  # no temporary left

    kinds = [(e.kind, e.message) for e in store.events(iid)]
    assert kinds == [("state", f"running: part {PART}, serial SN-1"),
                     ("state", "complete: fail (hole_2 position out of tolerance)")]
    assert json.dumps(again.to_json())  # serialisable for the API and the CLI


def test_filters_and_paging_newest_first(store):
    ids = {}
    for i, (part, serial, result) in enumerate([("P-A", "S1", "pass"), ("P-A", "S2", "fail"), ("P-B", "S3", "pass"),
                                                ("P-A", "S4", None), ("P-B", "S5", "fail")]):
        iid = store.begin_inspection(part, serial=serial, started_at=T0 + timedelta(minutes=i))
        if result is None:
            store.finish(iid, "aborted", reason="operator abort")
        else:
            store.record_characteristic(iid, Measurement("c", 1.0, 0.5, 1.5, 1.0, result == "pass"))
            store.finish(iid, "complete", result)
        ids[serial] = iid

    def serials(**kw):
        return [r.serial for r in store.list_inspections(**kw)]

    assert serials() == ["S5", "S4", "S3", "S2", "S1"]
    assert serials(part_number="P-A") == ["S4", "S2", "S1"]
    assert serials(result="pass") == ["S3", "S1"]
    assert serials(state="aborted") == ["S4"]
    assert serials(serial="S2") == ["S2"]
    assert serials(part_number="P-B", result="fail") == ["S5"]
    assert serials(since=T0 + timedelta(minutes=1), until=T0 + timedelta(minutes=3)) == ["S3", "S2"]
    assert store.count_inspections(part_number="P-A") == 3

    pages = [serials(limit=2, offset=o) for o in (0, 2, 4)]
    assert pages == [["S5", "S4"], ["S3", "S2"], ["S1"]]
    with pytest.raises(ValueError):
        store.list_inspections(result="maybe")
    with pytest.raises(ValueError):
        store.list_inspections(since=datetime(2025, 1, 1))  # naive: whose time?


def test_idempotency_key_is_unique_and_names_the_holder(store):
    first = store.begin_inspection(PART, idempotency_key="mes-42")
    with pytest.raises(DuplicateIdempotencyKey) as info:
        store.begin_inspection(PART, serial="other", idempotency_key="mes-42")
    assert info.value.inspection_id == first
    assert store.count_inspections() == 1  # the refused one left nothing
    assert store.find_by_idempotency_key("mes-42") == first
    # no key: as many as wanted (NULLs never collide)
    store.begin_inspection(PART)
    store.begin_inspection(PART)
    assert store.count_inspections() == 3


def test_results_of_a_finished_inspection_are_final(store, spec):
    iid = store.begin_inspection(PART)
    store.record_characteristic(iid, _m(spec, "hole_1.diameter", 0.7))
    with pytest.raises(StoreIntegrityError, match="already has a result for hole_1.diameter"):
        store.record_characteristic(iid, _m(spec, "hole_1.diameter", 0.71))
    # a pass with a failed characteristic is a contradiction: refused, nothing written
    with pytest.raises(ValueError, match="all passed"):
        store.finish(iid, "complete", "pass", measurements=[_m(spec, "hole_2.position", 85.08)])
    assert store.get(iid).state == "running" and len(store.get(iid).characteristics) == 1
    store.finish(iid, "complete", "pass")
    with pytest.raises(InspectionStateError, match="complete"):
        store.record_characteristic(iid, _m(spec, "hole_2.diameter", 0.7))
    with pytest.raises(InspectionStateError):
        store.add_image(iid, "hole_2", "late", np.zeros((4, 4), np.uint8))
    with pytest.raises(InspectionStateError):
        store.finish(iid, "aborted")
    with pytest.raises(InspectionNotFound):
        store.get("00000000-0000-0000-0000-000000000000")
    with pytest.raises(ValueError):
        store.finish(iid, "interrupted")  # only recovery interrupts
    with pytest.raises(ValueError):
        Measurement("x", 1.0, 0.5, 1.5, None, True)  # not measured cannot pass


def test_findings_and_machine_time_are_committed_with_the_result(store, spec):
    iid = store.begin_inspection(PART, serial="SN-F")
    stray = FindingRecord("unexpected_hole", "unexpected hole of 0.600 mm at 78.000 mm, 40.00 deg on the table",
                          axial_mm=78.0, angle_deg=40.0, diameter_mm=0.6, u_mm=0.003)
    datum = FindingRecord("datum", "part's angular datum 12.000 deg on the table, set by hole_1", subject="hole_1",
                          axial_mm=71.03, angle_deg=12.0)
    cycle = {"machine_s": 7.1, "basis": "modelled", "breakdown": {"moves_s": 5.8}}
    rec = store.finish(iid, "complete", "pass", measurements=[_m(spec, "hole_1.diameter", 0.7)],
                       findings=[datum, stray], machine_s=7.1, cycle=cycle)
    assert rec.findings == (datum, stray)
    assert rec.machine_s == 7.1 and rec.cycle == cycle
    assert rec.to_json()["findings"][1]["kind"] == "unexpected_hole"
    assert store.list_inspections(serial="SN-F")[0].machine_s == 7.1
    # refused before anything is written: nonsense kinds, times and types
    bad = store.begin_inspection(PART)
    with pytest.raises(ValueError, match="finding kind"):
        FindingRecord("burr", "a burr")
    with pytest.raises(ValueError, match="finite"):
        FindingRecord("datum", "d", axial_mm=float("nan"))
    with pytest.raises(ValueError, match="machine_s"):
        store.finish(bad, "aborted", machine_s=-1.0)
    with pytest.raises(TypeError, match="FindingRecord"):
        store.finish(bad, "aborted", findings=[{"kind": "datum"}])
    assert store.get(bad).state == "running"
    # an aborted one keeps its machine time too, and has no findings
    rec = store.finish(bad, "aborted", reason="stopped", machine_s=2.5, cycle={"machine_s": 2.5})
    assert (rec.machine_s, rec.findings) == (2.5, ())


def test_image_names_cannot_escape_the_folder(store, tmp_path):
    iid = store.begin_inspection(PART)
    crop = np.zeros((8, 8, 3), np.uint8)
    for name in ("../evil", "a/b", "/etc/passwd", ".hidden", "..", "x\\y", ""):
        with pytest.raises(ValueError, match="refused"):
            store.add_image(iid, "hole_1", name, crop)
    with pytest.raises(ValueError):
        store.add_image("../../etc", "hole_1", "x", crop)  # the id is checked too
    with pytest.raises(ValueError, match="uint8"):
        store.add_image(iid, "hole_1", "float", crop.astype(np.float32))
    store.add_image(iid, "hole_1", "ok.png", crop)
    with pytest.raises(StoreIntegrityError):
        store.add_image(iid, "hole_1", "ok", np.full((8, 8, 3), 255, np.uint8))  # never overwritten
    written = sorted(p.relative_to(store.data_dir).as_posix() for p in store.data_dir.rglob("*.png"))
    assert written == [f"images/{iid}/ok.png"]
    assert cv2.imread(str(store.data_dir / written[0])).max() == 0


def test_event_log_is_append_only(store):
    store.log_event("alarm", "Z axis following error")
    with store._write_sessions() as s:
        ev = s.scalars(select(Event)).one()
        ev.message = "nothing happened"
        with pytest.raises(StoreError, match="append-only"):
            s.commit()
        s.rollback()
        s.delete(ev)
        with pytest.raises(StoreError, match="append-only"):
            s.commit()
        s.rollback()
    assert [e.message for e in store.events(kind="alarm")] == ["Z axis following error"]


def test_one_owner_per_data_folder_and_readers_do_not_recover(store, tmp_path):
    iid = store.begin_inspection(PART)
    with pytest.raises(StoreLocked, match="another station process"):
        Store.open(data_dir=store.data_dir)
    with Store(data_dir=store.data_dir) as reader:  # a report or the CLI
        assert reader.get(iid).state == "running"  # the live inspection is not cut off


def _child(data_dir: Path, body: str, url: str | None = None) -> subprocess.Popen:
    code = textwrap.dedent(f"""
        import sys
        from station.store import Store, Measurement
        store = Store.open({url!r}, data_dir={str(data_dir)!r})
        iid = store.begin_inspection("{PART}", serial="killed")
        print(iid, flush=True)
    """) + textwrap.dedent(body)
    return subprocess.Popen([sys.executable, "-c", code], cwd=REPO, stdout=subprocess.PIPE, text=True)


def _kill(proc: subprocess.Popen) -> None:
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait()
    proc.stdout.close()


def _integrity(data_dir: Path, url: str) -> str:
    """SQLite's own check of the file; on PostgreSQL (whose server was never killed, only
    its client) every row of every table read back through the store's models."""
    if url.startswith("sqlite"):
        with sqlite3.connect(data_dir / "station.db") as con:
            return con.execute("PRAGMA integrity_check").fetchone()[0]
    from sqlalchemy import select
    from sqlalchemy.orm import Session

    from station.store.models import Base

    engine = make_engine(url)
    try:
        with Session(engine) as s:
            for mapper in Base.registry.mappers:
                s.scalars(select(mapper.class_)).all()
    finally:
        engine.dispose()
    return "ok"


def test_killed_process_leaves_an_interrupted_inspection(tmp_path, db_url):
    data = tmp_path / "data"
    url = db_url(data)
    proc = _child(data, url=url, body="""
        for i in range(3):
            store.record_characteristic(iid, Measurement(f"c{i}", 1.0, 0.5, 1.5, 1.0 + i / 10, True))
        print("recorded", flush=True)
        import time
        while True:
            time.sleep(1)  # waits here to be killed, never finishes
    """)
    try:
        iid = proc.stdout.readline().strip()
        assert proc.stdout.readline().strip() == "recorded"
    finally:
        _kill(proc)
    assert proc.returncode == -signal.SIGKILL

    with Store.open(data_dir=data) as store:
        rec = store.get(iid)
        assert rec.state == "interrupted" and rec.result is None and rec.finished_at is not None
        assert "stopped before the inspection finished" in rec.reason
        assert [c.characteristic_id for c in rec.characteristics] == ["c0", "c1", "c2"]
        assert [e.message.split(":")[0] for e in store.events(iid, kind="state")] == ["running", "interrupted"]
        assert store.recover_interrupted() == []  # nothing left to recover
    assert _integrity(data, url) == "ok"


def test_kill_while_writing_keeps_every_reported_result(tmp_path, db_url):
    """A process killed in the middle of a stream of commits: every result it reported
    (printed after the call returned) is in the store, and the database is sound."""
    data = tmp_path / "data"
    url = db_url(data)
    proc = _child(data, url=url, body="""
        i = 0
        while True:
            store.record_characteristic(iid, Measurement(f"c{i}", 1.0, 0.5, 1.5, 1.0, True))
            print(f"c{i}", flush=True)
            i += 1
    """)
    reported = []
    try:
        iid = proc.stdout.readline().strip()
        while len(reported) < 20:
            reported.append(proc.stdout.readline().strip())
    finally:
        _kill(proc)
    assert _integrity(data, url) == "ok"
    with Store.open(data_dir=data) as store:
        rec = store.get(iid)
        stored = [c.characteristic_id for c in rec.characteristics]
        assert stored[: len(reported)] == reported
        assert stored == [f"c{i}" for i in range(len(stored))]  # no gap, no half row
        assert rec.state == "interrupted"


def test_migrated_schema_equals_the_models(tmp_path, empty_db_url):
    url = empty_db_url(tmp_path / "m")
    upgrade_to_head(url)
    upgrade_to_head(url)  # a second run has nothing to do
    engine = make_engine(url)
    try:
        with engine.connect() as conn:
            assert current_revision(conn) == head_revision()
            ctx = MigrationContext.configure(conn, opts={"compare_type": True, "compare_server_default": True})
            assert compare_metadata(ctx, Base.metadata) == []
            assert set(inspect(conn).get_table_names()) == set(Base.metadata.tables) | {"alembic_version"}
            # the comparison does see a difference when there is one
            conn.exec_driver_sql("DROP INDEX ix_inspection_serial")
            diffs = compare_metadata(ctx, Base.metadata)
            assert [d[0] for d in diffs] == ["add_index"]
            conn.commit()
        cfg = alembic_config()
        with engine.connect() as conn:  # the downgrade undoes the revision (less the dropped index)
            conn.exec_driver_sql("CREATE INDEX ix_inspection_serial ON inspection (serial)")
            cfg.attributes["connection"] = conn
            command.downgrade(cfg, "base")
            conn.commit()
            assert inspect(conn).get_table_names() == ["alembic_version"]
    finally:
        engine.dispose()


def test_locked_database_raises_store_error(tmp_path, db_backend):
    """Another process holds the lock a write needs: the store waits its busy timeout,
    then raises StoreUnavailable naming the database; nothing is written, and the store
    works once the lock is gone. SQLite: an exclusive transaction on the file;
    PostgreSQL: an exclusive lock on the table (lock_timeout)."""
    data = tmp_path / "data"
    with Store(data_dir=data, busy_timeout_s=0.05) as store:
        iid = store.begin_inspection(PART)
        if db_backend == "sqlite":
            other = sqlite3.connect(data / "station.db", isolation_level=None, timeout=0.05)
            other.execute("BEGIN EXCLUSIVE")
            release = lambda: (other.execute("ROLLBACK"), other.close())  # noqa: E731
            where = str(data / "station.db")
        else:
            other_engine = make_engine(store.url)
            other = other_engine.connect()
            other.exec_driver_sql("LOCK TABLE characteristic_result, inspection IN ACCESS EXCLUSIVE MODE")
            release = lambda: (other.rollback(), other.close(), other_engine.dispose())  # noqa: E731
            where = store._where()
        try:
            with pytest.raises(StoreUnavailable, match="locked by another process") as info:
                store.record_characteristic(iid, Measurement("c", 1.0, 0.5, 1.5, 1.0, True))
            assert isinstance(info.value, StoreError) and where in str(info.value)
            with pytest.raises(StoreUnavailable, match="locked"):
                store.finish(iid, "aborted")
        finally:
            release()
        assert store.get(iid).characteristics == ()  # the refused call wrote nothing
        store.finish(iid, "aborted")  # and the store works once the lock is gone
        assert store.get(iid).state == "aborted"


def test_full_or_read_only_database_raises_store_error(tmp_path, db_backend):
    """SQLite: max_page_count caps the file, which fails exactly as a full disk does.
    PostgreSQL: the database turned read-only (as a standby after a failover is), which
    fails every write the same way. Either: StoreUnavailable saying why, nothing written."""
    with Store(data_dir=tmp_path / "data") as store:
        store.engine.dispose()  # new connections get the cap
        if db_backend == "sqlite":
            @event.listens_for(store.engine, "connect")
            def _cap(dbapi_conn, _rec):
                pages = dbapi_conn.execute("PRAGMA page_count").fetchone()[0]
                dbapi_conn.execute(f"PRAGMA max_page_count = {pages}")
            why = "full"
        else:
            @event.listens_for(store.engine, "connect")
            def _read_only(dbapi_conn, _rec):
                dbapi_conn.execute("SET SESSION CHARACTERISTICS AS TRANSACTION READ ONLY")
                dbapi_conn.commit()
            why = "read-only"

        with pytest.raises(StoreUnavailable, match=why):
            store.log_event("info", "x" * 200_000)
        assert store.events() == []


def test_cli_results_list_and_show(tmp_path, spec):
    data = tmp_path / "data"
    with Store.open(data_dir=data) as store:
        a = store.begin_inspection(PART, serial="SN-A", started_at=T0)
        store.finish(a, "complete", "pass", measurements=[_m(spec, c.id, c.nominal) for c in spec.characteristics()])
        b = store.begin_inspection(PART, serial="SN-B", started_at=T0 + timedelta(hours=1))
        store.finish(b, "complete", "fail", measurements=[_m(spec, "hole_2.position", 85.08)])
    runner = CliRunner()
    listed = runner.invoke(app, ["results", "list", "--data", str(data), "--json"])
    assert listed.exit_code == 0, listed.output
    assert [r["serial"] for r in json.loads(listed.stdout)] == ["SN-B", "SN-A"]
    failed = runner.invoke(app, ["results", "list", "--data", str(data), "--result", "fail", "--json"])
    assert [r["id"] for r in json.loads(failed.stdout)] == [b]
    by_station = runner.invoke(app, ["results", "list", "--data", str(data), "--station", "nowhere", "--json"])
    assert by_station.exit_code == 0 and json.loads(by_station.stdout) == []
    limited = runner.invoke(app, ["results", "list", "--data", str(data), "--limit", "1", "--serial", "SN-A"])
    assert limited.exit_code == 0 and "SN-A" in limited.stdout and "SN-B" not in limited.stdout

    shown = runner.invoke(app, ["results", "show", a, "--data", str(data), "--json"])
    assert shown.exit_code == 0
    assert len(json.loads(shown.stdout)["characteristics"]) == 4
    table = runner.invoke(app, ["results", "show", b, "--data", str(data)])
    assert table.exit_code == 0 and "hole_2.position" in table.stdout and "85.08" in table.stdout
    missing = runner.invoke(app, ["results", "show", "nope", "--data", str(data)])
    assert missing.exit_code != 0 and "no inspection" in missing.stderr
    empty = runner.invoke(app, ["results", "list", "--data", str(tmp_path / "none"), "--json"])
    assert empty.exit_code == 0 and json.loads(empty.stdout) == []
    assert not (tmp_path / "none").exists()  # reading never creates a store


def test_connections_are_durable_and_writes_lock_early(store, db_backend):
    """SQLite: WAL, synchronous=FULL, foreign keys on; writes begin IMMEDIATE (the write
    lock is waited for at BEGIN), reads plain BEGIN (they never block the station).
    PostgreSQL: every connection commits synchronously whatever the server's default
    (the test cluster's is off), waits for a lock no longer than the busy timeout, and
    bounds every statement; the rows a write changes are locked FOR UPDATE."""
    seen = []

    @event.listens_for(store.engine, "before_cursor_execute")
    def _seen(_conn, _cur, statement, *_args):
        seen.append(statement)

    if db_backend == "sqlite":
        with store.engine.connect() as conn:
            pragma = {p: conn.exec_driver_sql(f"PRAGMA {p}").scalar() for p in ("journal_mode", "synchronous",
                                                                                 "foreign_keys", "busy_timeout")}
        assert pragma == {"journal_mode": "wal", "synchronous": 2, "foreign_keys": 1, "busy_timeout": 5000}
        seen.clear()
        iid = store.begin_inspection(PART)
        store.get(iid)
        assert [b for b in seen if b.startswith("BEGIN")] == ["BEGIN IMMEDIATE", "BEGIN"]
    else:
        with store.engine.connect() as conn:
            shown = {p: conn.exec_driver_sql(f"SHOW {p}").scalar() for p in ("synchronous_commit", "lock_timeout",
                                                                              "statement_timeout")}
        assert shown == {"synchronous_commit": "on", "lock_timeout": "5s", "statement_timeout": "1min"}
        iid = store.begin_inspection(PART)
        seen.clear()
        store.record_characteristic(iid, Measurement("c", 1.0, 0.5, 1.5, 1.0, True))
        assert any("FOR UPDATE" in q for q in seen)


def test_database_of_a_newer_station_and_odd_traceability_are_refused(tmp_path):
    data = tmp_path / "data"
    with Store(data_dir=data) as store:
        with pytest.raises(ValueError, match="plain JSON"):
            store.begin_inspection(PART, traceability={"calibration": object()})
        with pytest.raises(ValueError, match="naive"):
            store.begin_inspection(PART, started_at=datetime(2025, 1, 1))
        assert store.count_inspections() == 0
        with store.engine.begin() as conn:  # as a newer station would leave it
            conn.exec_driver_sql("UPDATE alembic_version SET version_num = '0999'")
    with pytest.raises(StoreError, match="schema up to date: Can't locate revision"):
        Store(data_dir=data)


def test_texts_with_nul_find_nothing_and_json_keeps_no_nan(store):
    """Both backends alike: a NUL character is refused in stored text and finds nothing
    in a lookup (PostgreSQL cannot hold one; a path parameter may carry one), and a
    non-finite number in a stored JSON document becomes null (JSON has no NaN)."""
    iid = store.begin_inspection(PART, serial="SN-NUL")
    with pytest.raises(ValueError, match="NUL"):
        store.begin_inspection(PART, serial="SN\x00X")
    with pytest.raises(InspectionNotFound):
        store.get(iid + "\x00")
    assert store.find_by_idempotency_key("k\x00") is None
    assert store.list_inspections(serial="SN-NUL\x00") == [] and store.count_inspections(station="a\x00") == 0
    assert store.events(iid + "\x00") == []
    store.finish(iid, "aborted", machine_s=1.0,
                 cycle={"ratio": float("nan"), "parts": [float("inf"), 1.0], "lower_bound_s": 0.0})
    assert dict(store.get(iid).cycle) == {"ratio": None, "parts": [None, 1.0], "lower_bound_s": 0.0}


class _LockedCursor:
    """A cursor whose database answers "locked" to the first ``n`` WAL requests."""

    def __init__(self, n: int, message: str = "database is locked"):
        self.n, self.message, self.calls = n, message, []

    def execute(self, sql: str):
        self.calls.append((time.monotonic(), sql))
        if len(self.calls) <= self.n:
            raise sqlite3.OperationalError(self.message)


def test_a_new_database_turned_to_wal_by_another_process_is_waited_for_not_failed():
    """Processes opening a new file together each ask for WAL; SQLite answers the
    losers "locked" at once (a deadlock, no busy handler). The request is made again,
    backing off, until the timeout; other errors and a lock held too long still fail."""
    cur = _LockedCursor(4)
    _set_wal(cur, 5.0)
    assert len(cur.calls) == 5 and all(sql == "PRAGMA journal_mode = WAL" for _t, sql in cur.calls)
    gaps = np.diff([t for t, _sql in cur.calls])
    assert gaps.min() > 0.001 and gaps.sum() < 1.0  # backed off, briefly

    held = _LockedCursor(10**6)
    t0 = time.monotonic()
    with pytest.raises(sqlite3.OperationalError, match="locked"):
        _set_wal(held, 0.3)
    assert 0.1 < time.monotonic() - t0 < 2.0 and len(held.calls) > 2  # ~0.2 s of back-off

    other = _LockedCursor(1, "disk I/O error")
    with pytest.raises(sqlite3.OperationalError, match="disk I/O"):
        _set_wal(other, 5.0)
    assert len(other.calls) == 1


def test_stations_starting_together_migrate_an_empty_database_once(tmp_path, empty_db_url):
    """Four processes open one empty database at the same moment (stations starting
    together after a plant-wide update): every one opens it, the schema is made once
    (one revision row, the newest), none fails on another's half-made tables."""
    url = empty_db_url(tmp_path / "shared")
    code = textwrap.dedent(f"""
        import sys, time
        from station.store import Store
        t0 = float(sys.argv[1])
        time.sleep(max(0.0, t0 - time.time()))  # all at once
        with Store({url!r}, data_dir=sys.argv[2]) as store:
            print(store.count_inspections(), flush=True)
    """)
    start = time.time() + 3.0
    procs = [subprocess.Popen([sys.executable, "-c", code, str(start), str(tmp_path / f"st{i}")], cwd=REPO,
                              stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True) for i in range(4)]
    outs = [p.communicate(timeout=120) for p in procs]
    assert [p.returncode for p in procs] == [0] * 4, [err[-800:] for _out, err in outs]
    assert [out.strip() for out, _err in outs] == ["0"] * 4
    engine = make_engine(url)
    try:
        with engine.connect() as conn:
            assert conn.exec_driver_sql("SELECT version_num FROM alembic_version").scalars().all() == [head_revision()]
    finally:
        engine.dispose()


def test_each_station_recovers_and_reads_its_own(tmp_path):
    """Two stations on one database: a station opening the store marks its own running
    inspections interrupted, never the other's; lists and events filter by station;
    events older than station ids count as any station's own where asked."""
    data = tmp_path / "data"
    with Store(data_dir=data) as legacy:  # written before stations had ids
        legacy.log_event("alarm", "an old alarm")
    with Store(data_dir=data, station_id="st-a") as a, Store(data_dir=data, station_id="st-b") as b:
        ia, ib = a.begin_inspection(PART, serial="A1"), b.begin_inspection(PART, serial="B1")
        a.log_event("alarm", "a's alarm")
        assert a.recover_interrupted() == [ia]  # as st-a's restart does
        assert b.get(ib).state == "running"  # st-b's inspection runs on
        assert [s.id for s in a.list_inspections(station="st-b")] == [ib]
        assert a.count_inspections(station="st-a") == 1 and a.stations() == ["st-a", "st-b"]
        assert a.get(ia).station_id == "st-a" and b.get(ib).station_id == "st-b"
        assert [e.message for e in a.events(kind="alarm", station="st-a")] == ["a's alarm"]
        assert [e.message for e in a.events(kind="alarm", station="st-a", with_unassigned=True)] == \
            ["an old alarm", "a's alarm"]
        assert [e.message for e in b.events(kind="alarm", station="st-b", with_unassigned=True)] == ["an old alarm"]
    with pytest.raises(ValueError, match="station id"):
        Store(data_dir=data, station_id="no spaces")


def test_one_live_process_per_station_id(tmp_path, db_url, db_backend):
    """Two station processes with one id would cut off each other's inspections at
    start: the second is refused. SQLite: the data folder's file lock (one database per
    folder). PostgreSQL: a session advisory lock per id on the shared database, across
    data folders; another id opens, and the id is free again once its holder closes."""
    url = db_url(tmp_path / "a")
    first = Store.open(url, data_dir=tmp_path / "a", station_id="st-1")
    try:
        if db_backend == "sqlite":
            with pytest.raises(StoreLocked, match="another station process"):
                Store.open(url, data_dir=tmp_path / "a", station_id="st-2")
        else:
            with pytest.raises(StoreLocked, match="station id 'st-1'"):
                Store.open(url, data_dir=tmp_path / "b", station_id="st-1")
            Store.open(url, data_dir=tmp_path / "c", station_id="st-2").close()
    finally:
        first.close()
    Store.open(url, data_dir=tmp_path / "b", station_id="st-1").close()
