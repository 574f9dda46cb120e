"""The whole-surface inspection in the results store (issue 23): the surface document
(``inspection.surface``, migration 0006) and the unrolled picture (an image of the
record, subject ``surface``) go in with the finish's commit and come back as they went
in; a record without a surface keeps null; nothing of a refused or failed finish is
left behind (no document, no picture file); the StoreWriter stores them from the stop
document, with the twin's truth as it stores a characteristic's ``true_value``; the
migration adds and drops the column on a database that already has records.

On SQLite here (and on PostgreSQL with ``--db postgresql``; ``make test``'s PostgreSQL
run covers the same round trip through tests/api/test_surface_api.py)."""

from __future__ import annotations

import asyncio
import hashlib
import json

import cv2
import numpy as np
import pytest
from alembic import command
from sqlalchemy import event, inspect

from station.inspection.documents import CheckDocument, InspectionStart, InspectionStop
from station.inspection.service import CharacteristicOutcome, InspectionOutcome
from station.inspection.writers import StoreWriter
from station.parts import load_part
from station.store import Measurement, Store, StoreUnavailable
from station.store.engine import make_engine
from station.store.migrate import alembic_config
from surface_cases import DEFECTS, store_surface_record, synthetic_surface

PART = "ZDZG-22.2-12.3851"


@pytest.fixture
def store(tmp_path):
    s = Store.open(data_dir=tmp_path / "data")
    yield s
    s.close()


def _files(store, iid) -> list[str]:
    folder = store.data_dir / "images" / iid
    return sorted(p.name for p in folder.iterdir()) if folder.is_dir() else []


def test_surface_document_and_picture_round_trip(store):
    surface = synthetic_surface()
    iid = store_surface_record(store, "SN-S1", surface)
    rec = store.get(iid)

    # the document as the writer gave it, truth included (simulation bookkeeping, as true_value)
    assert rec.surface == surface.to_json(with_truth=True)
    assert [d["id"] for d in rec.surface["defects"]] == [d[0] for d in DEFECTS]
    assert rec.surface["defects"][0]["truth"]["axial_mm"] == 65.0
    assert rec.surface["picture"]["width_px"] == surface.picture.width_px
    assert rec.surface["picture"]["deg_per_px"] == pytest.approx(surface.picture.deg_per_px, rel=1e-12)
    assert rec.to_json()["surface"] == rec.surface  # the record's JSON carries it
    assert json.dumps(rec.to_json(), allow_nan=False)

    # the picture: an image of the record, PNG under the data folder, its SHA-256 recorded
    pic = rec.surface_image()
    assert pic is not None and pic.subject == "surface" and pic.path == f"images/{iid}/surface.png"
    assert [i.subject for i in rec.images] == ["surface"]
    on_disk = store.image_path(pic)
    assert hashlib.sha256(on_disk.read_bytes()).hexdigest() == pic.sha256
    np.testing.assert_array_equal(cv2.imread(str(on_disk), cv2.IMREAD_UNCHANGED), surface.picture.image)
    assert _files(store, iid) == ["surface.png"]  # no temporary file left

    # a list reads the headers only (the document stays in the row, not in every summary)
    (summary,) = store.list_inspections(serial="SN-S1")
    assert not hasattr(summary, "surface") and "surface" not in summary.to_json()


def test_a_record_without_surface_keeps_null(store):
    iid = store_surface_record(store, "SN-S0", None, result="pass")
    rec = store.get(iid)
    assert rec.surface is None and rec.surface_image() is None and rec.images == ()
    assert rec.to_json()["surface"] is None
    # a surface without a picture: the document, no image
    iid = store_surface_record(store, "SN-S2", synthetic_surface(with_picture=False))
    rec = store.get(iid)
    assert rec.surface["picture"] is None and len(rec.surface["defects"]) == len(DEFECTS)
    assert rec.surface_image() is None and rec.images == () and _files(store, iid) == []


def test_surface_document_is_plain_json_or_refused(store):
    spec = load_part(PART)
    c = spec.characteristic("hole_1.diameter")
    m = Measurement.of(c, c.nominal, passed=True)
    iid = store.begin_inspection(PART)
    # numpy numbers (a count or a size computed with numpy) are numbers; NaN is null
    doc = {"frames": np.int64(12), "coverage": float("nan"), "defects": [{"length_mm": np.float32(0.25)}],
           "picture": None}
    rec = store.finish(iid, "complete", "pass", measurements=[m], surface=doc)
    assert rec.surface == {"frames": 12, "coverage": None, "defects": [{"length_mm": 0.25}], "picture": None}
    # not JSON: refused before anything is written
    bad = store.begin_inspection(PART)
    with pytest.raises(ValueError, match="surface must be plain JSON"):
        store.finish(bad, "complete", "pass", measurements=[m], surface={"when": object()})
    with pytest.raises(ValueError, match="surface must be a JSON object"):
        store.finish(bad, "complete", "pass", measurements=[m], surface=[1, 2])
    with pytest.raises(TypeError, match="subject, name"):
        store.finish(bad, "complete", "pass", measurements=[m], images=[np.zeros((4, 4), np.uint8)])
    assert store.get(bad).state == "running" and store.get(bad).characteristics == ()


def test_nothing_of_a_failed_finish_is_left(store):
    """The document and the picture go with the result or not at all: a refused finish
    (a pass with a failed characteristic) and a failed commit (the disk full at the
    transaction's last statement, the state event) leave no document, no image row and
    no file, and the inspection can still be finished."""
    spec = load_part(PART)
    c = spec.characteristic("hole_1.diameter")
    surface = synthetic_surface()
    from station.inspection.writers import surface_fields

    iid = store.begin_inspection(PART, serial="SN-F")
    with pytest.raises(ValueError, match="a pass needs"):
        store.finish(iid, "complete", "pass", measurements=[Measurement.of(c, 9.9, passed=False)],
                     **surface_fields(surface))
    assert _files(store, iid) == []
    rec = store.get(iid)
    assert rec.state == "running" and rec.surface is None and rec.images == ()

    if store.engine.dialect.name == "postgresql":  # as each driver raises it (testkit/injector.py)
        import psycopg.errors

        def error():
            return psycopg.errors.DiskFull('could not extend file "base/1/2": No space left on device')
    else:
        import sqlite3

        def error():
            return sqlite3.OperationalError("database or disk is full")

    def full(conn, cursor, statement, parameters, context, executemany):
        if statement.lstrip().upper().startswith("INSERT INTO EVENT"):
            raise error()

    event.listen(store.engine, "before_cursor_execute", full)
    try:
        with pytest.raises(StoreUnavailable, match="full|space"):
            store.finish(iid, "complete", "fail", measurements=[Measurement.of(c, 9.9, passed=False)],
                         **surface_fields(surface))
    finally:
        event.remove(store.engine, "before_cursor_execute", full)
    assert _files(store, iid) == []  # published only after every statement ran
    rec = store.get(iid)
    assert rec.state == "running" and rec.surface is None and rec.images == () and rec.characteristics == ()

    rec = store.finish(iid, "complete", "fail", measurements=[Measurement.of(c, 9.9, passed=False)],
                       **surface_fields(surface))
    assert rec.surface is not None and rec.surface_image() is not None and _files(store, iid) == ["surface.png"]


def _run_writer(store, outcome: InspectionOutcome, iid: str) -> None:
    spec = load_part(PART)
    c = spec.characteristic("hole_1.diameter")
    writer = StoreWriter(store)
    check = CharacteristicOutcome(c.id, c.nominal, c.lower_limit, c.upper_limit, 0.7, 0.004, True, true_value=0.7001)

    async def run():
        await writer(InspectionStart(iid, part_number=PART, serial=outcome.serial))
        await writer(CheckDocument(iid, characteristic=check))
        await writer(InspectionStop(iid, outcome=outcome))

    asyncio.run(run())


@pytest.mark.parametrize("with_surface", [True, False], ids=["surface", "no-surface"])
def test_the_store_writer_commits_the_surface_with_the_result(store, with_surface):
    import uuid

    iid = str(uuid.uuid4())
    surface = synthetic_surface() if with_surface else None
    outcome = InspectionOutcome(iid, PART, "SN-W", "complete", "pass", surface=surface)
    _run_writer(store, outcome, iid)
    rec = store.get(iid)
    assert (rec.state, rec.result) == ("complete", "pass")
    assert rec.characteristic("hole_1.diameter").true_value == 0.7001  # the truth the writer keeps ...
    if not with_surface:
        assert rec.surface is None and rec.images == ()
        return
    assert rec.surface == surface.to_json(with_truth=True)  # ... and the defects' truth beside it
    assert all(d["truth"] is not None for d in rec.surface["defects"])
    np.testing.assert_array_equal(cv2.imread(str(store.image_path(rec.surface_image())), cv2.IMREAD_UNCHANGED),
                                  surface.picture.image)
    # the state event is the last thing committed: the surface was in that commit
    assert [e.message for e in store.events(iid)][-1] == "complete: pass"


def test_a_surface_the_store_refuses_faults_the_record(store):
    """A picture that is no uint8 image (a bug upstream): the result is not stored, the
    record ends faulted with the reason and an alarm (never left running), no file."""
    import uuid

    from station.inspection.writers import ResultNotStored

    iid = str(uuid.uuid4())
    surface = synthetic_surface()
    surface.picture.image = surface.picture.image.astype(np.float32)
    outcome = InspectionOutcome(iid, PART, "SN-BAD", "complete", "pass", surface=surface)
    with pytest.raises(ResultNotStored, match="uint8"):
        _run_writer(store, outcome, iid)
    rec = store.get(iid)
    assert rec.state == "faulted" and "uint8" in rec.reason and rec.surface is None and rec.images == ()
    assert any(e.kind == "alarm" and "uint8" in e.message for e in store.events(iid))
    assert _files(store, iid) == []


def test_an_incomplete_inspection_stores_no_surface(store):
    import uuid

    iid = str(uuid.uuid4())
    outcome = InspectionOutcome(iid, PART, "SN-A", "aborted", None, reason="stopped", surface=synthetic_surface())
    _run_writer(store, outcome, iid)
    rec = store.get(iid)
    assert rec.state == "aborted" and rec.surface is None and rec.images == ()


def test_migration_0006_adds_and_drops_the_column(tmp_path, empty_db_url):
    """From 0005 with a record in it: the upgrade keeps the record with a null surface;
    the downgrade to 0005 drops the column and keeps the record."""
    url = empty_db_url(tmp_path / "m6")
    engine = make_engine(url)
    cfg = alembic_config()
    try:
        with engine.connect() as conn:
            cfg.attributes["connection"] = conn
            command.upgrade(cfg, "0005")
            conn.exec_driver_sql(
                "INSERT INTO inspection (id, part_number, state, started_at, finished_at, result, traceability) "
                "VALUES ('00000000-0000-4000-8000-000000000006', 'P-1', 'complete', '2025-01-01 00:00:00', "
                "'2025-01-01 00:01:00', 'pass', '{}')")
            conn.commit()
            assert "surface" not in {c["name"] for c in inspect(conn).get_columns("inspection")}
            command.upgrade(cfg, "0006")
            conn.commit()
        with engine.connect() as conn:
            assert "surface" in {c["name"] for c in inspect(conn).get_columns("inspection")}
            assert conn.exec_driver_sql("SELECT id, surface FROM inspection").all() == [
                ("00000000-0000-4000-8000-000000000006", None)]
            cfg.attributes["connection"] = conn
            command.downgrade(cfg, "0005")
            conn.commit()
        with engine.connect() as conn:
            assert "surface" not in {c["name"] for c in inspect(conn).get_columns("inspection")}
            assert conn.exec_driver_sql("SELECT count(*) FROM inspection").scalar() == 1
    finally:
        engine.dispose()
