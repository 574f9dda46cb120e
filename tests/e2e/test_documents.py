"""An inspection as a stream of documents (issue 19): what every subscriber sees, in
which order, and what happens when a subscriber fails. On the simulated station,
through the real drivers."""

from __future__ import annotations

import asyncio

from station.inspection.documents import (CheckDocument, FrameDocument, HoleDocument, InspectionStart,
                                          InspectionStop)
from station.parts import load_part
from station.runtime import open_session
from station.store import Store
from station.store.errors import StoreUnavailable

PART = "ZDZG-22.2-12.3851"
TIME_SCALE = 50.0


def run(coro):
    return asyncio.run(asyncio.wait_for(coro, timeout=240))


def test_an_inspection_is_start_frames_holes_checks_stop_and_the_store_is_one_subscriber(tmp_path):
    spec = load_part(PART)
    docs = []

    def broken(doc):
        raise RuntimeError("a subscriber with a bug")

    async def go():
        async with open_session(time_scale=TIME_SCALE, data_dir=tmp_path) as s:
            s.documents.subscribe(docs.append)
            s.documents.subscribe(broken)  # optional: its failure must not cost the result
            out = await s.inspect(spec, "SN-DOCS")
            return out, list(s.documents.errors)

    out, errors = run(go())
    assert out.state == "complete", out.reason
    kinds = [d.kind for d in docs]
    # start first, stop last, frames before holes, holes before checks
    assert kinds[0] == "start" and kinds[-1] == "stop" and kinds.count("start") == kinds.count("stop") == 1
    last_frame = max(i for i, k in enumerate(kinds) if k == "frame")
    first_hole = kinds.index("hole")
    assert last_frame < first_hole < kinds.index("check")
    assert {d.inspection_id for d in docs} == {out.id}
    start = docs[0]
    assert isinstance(start, InspectionStart) and start.serial == "SN-DOCS" and start.purpose == "production"
    frames = [d for d in docs if isinstance(d, FrameDocument)]
    holes = [d.hole for d in docs if isinstance(d, HoleDocument)]
    assert [h.name for h in holes] == [h.name for h in out.holes]
    # every measurement frame of every hole went out live, in order, with its hole's name
    assert [(f.hole, f.index) for f in frames] == [(h.name, k) for h in holes for k in range(len(h.frames))]
    assert all(f.frame is h.frames[f.index] for h in holes for f in frames if f.hole == h.name)
    checks = [d.characteristic for d in docs if isinstance(d, CheckDocument)]
    assert [c.id for c in checks] == [c.id for c in out.characteristics]
    # the ground truth is an annotation by the composition root's subscriber
    assert all(c.true_value is not None for c in checks)
    stop = docs[-1]
    assert isinstance(stop, InspectionStop) and stop.outcome is out
    # the broken subscriber saw every document and failed on each, kept, not raised
    assert len(errors) == len(docs) and {e.error for e in errors} == {"RuntimeError: a subscriber with a bug"}
    with Store(data_dir=tmp_path) as store:
        rec = store.get(out.id)
        assert rec.state == "complete" and rec.result == out.result
        stored = {c.characteristic_id: c.measured for c in rec.characteristics}
        assert stored == {c.id: c.measured for c in out.characteristics}
        assert all(c.true_value is not None for c in rec.characteristics)
        # the engine's events of the inspection are logged under its id
        assert any(e.kind == "state" for e in store.events(inspection_id=out.id))
    # the scan log subscriber wrote the grating's evidence after the commit
    assert (tmp_path / "scanlogs" / f"{out.id}.csv").is_file()


def test_a_result_the_store_does_not_take_is_published_as_the_faulted_inspection_it_is(tmp_path):
    spec = load_part(PART)
    docs = []

    async def go():
        async with open_session(time_scale=TIME_SCALE, data_dir=tmp_path) as s:
            s.documents.subscribe(docs.append)
            real_finish = s.store.finish
            calls = []

            def failing_finish(iid, state, *a, **kw):
                calls.append(state)
                if state == "complete":
                    raise StoreUnavailable("disk full (test)")
                return real_finish(iid, state, *a, **kw)

            s.store.finish = failing_finish
            out = await s.inspect(spec, "SN-NOSTORE")
            s.store.finish = real_finish
            return out, calls

    out, calls = run(go())
    assert out.state == "faulted" and out.result is None and "result not stored" in out.reason
    assert calls == ["complete", "faulted"]
    stops = [d for d in docs if isinstance(d, InspectionStop)]
    # the complete stop never got past the store writer; the faulted one reached everyone
    assert len(stops) == 1 and stops[0].outcome.state == "faulted"
    assert not (tmp_path / "scanlogs" / f"{out.id}.csv").exists()
    with Store(data_dir=tmp_path) as store:
        rec = store.get(out.id)
        assert rec.state == "faulted" and "result not stored" in rec.reason


def test_a_check_on_the_master_says_so_in_its_start(tmp_path):
    from station.checks.master import load_master

    cert = load_master("MC-22.2-A")
    family = load_part(cert.part_number)
    docs = []

    async def go():
        async with open_session(time_scale=TIME_SCALE, data_dir=tmp_path) as s:
            s.documents.subscribe(docs.append)
            return await s.check_master(cert, family)

    chk = run(go())
    starts = [d for d in docs if isinstance(d, InspectionStart)]
    assert [(d.purpose, d.serial) for d in starts] == [("master", cert.master_id)]
    assert docs[-1].outcome is chk.inspection
