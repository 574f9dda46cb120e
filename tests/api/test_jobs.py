"""Job orders on the simulated station: start, poll to the end, idempotency, busy,
filters and paging."""

from __future__ import annotations

import uuid
from datetime import datetime, timedelta, timezone

import pytest

from station.sequencer.cycle import BREAKDOWN_KEYS
from tests.api.conftest import PART, wait_done, wait_idle


def order(serial: str, **kw) -> dict:
    return {"part_number": PART, "serial": serial, "order_id": kw.pop("order_id", "PO-1"), **kw}


def test_job_order_runs_to_a_passing_result(api):
    with api.client("mes") as c:
        r = c.post("/api/v1/job-orders", json=order("SN-API-1"), headers={"Idempotency-Key": str(uuid.uuid4())})
        assert r.status_code == 202, r.text
        job = r.json()
        assert job["state"] == "running" and job["part_number"] == PART and job["serial"] == "SN-API-1"
        assert r.headers["location"] == f"/api/v1/inspections/{job['id']}"
        done = wait_done(c, job["id"])
    assert done["state"] == "complete" and done["result"] == "pass", done["reason"]
    chars = {ch["id"]: ch for ch in done["characteristics"]}
    assert set(chars) == {"hole_1.diameter", "hole_1.position", "hole_2.diameter", "hole_2.position"}
    for ch in chars.values():
        assert ch["pass"] is True
        assert ch["lower_limit"] <= ch["measured"] <= ch["upper_limit"]
        assert ch["uncertainty_k2"] > 0 and ch["unit"] == "mm"
        assert "true_value" not in ch  # simulation bookkeeping stays out of the job response
    assert chars["hole_1.position"]["nominal"] == 71.03
    # the scan's findings: the standard part's angular datum is set by hole_1, where it was found
    datum = [f for f in done["findings"] if f["kind"] == "datum"]
    assert len(datum) == 1 and datum[0]["subject"] == "hole_1", done["findings"]
    assert "angular datum" in datum[0]["message"] and "hole_1" in datum[0]["message"]
    assert datum[0]["axial_mm"] == pytest.approx(chars["hole_1.position"]["measured"], abs=1e-9)
    assert datum[0]["diameter_mm"] == pytest.approx(chars["hole_1.diameter"]["measured"], abs=1e-9)
    assert datum[0]["u_mm"] > 0 and 0 <= datum[0]["angle_deg"] < 360
    assert not [f for f in done["findings"] if f["kind"] == "unexpected_hole"]
    # the machine time and how it divides
    assert done["machine_s"] > 0
    cycle = done["cycle"]
    assert cycle["machine_s"] == done["machine_s"] and cycle["basis"] == "modelled"  # a twin at time scale 50
    assert set(cycle["breakdown"]) == set(BREAKDOWN_KEYS)
    assert sum(cycle["breakdown"].values()) == pytest.approx(done["machine_s"], rel=1e-6)
    # the list carries the machine time too (findings only with the one inspection)
    with api.client("mes") as c:
        listed = c.get("/api/v1/inspections", params={"serial": "SN-API-1"}).json()["items"]
    assert [i["id"] for i in listed] == [job["id"]]
    assert listed[0]["machine_s"] == done["machine_s"] and listed[0]["cycle"] == cycle
    assert "findings" not in listed[0]


def test_the_served_station_gives_the_plans_lower_bound(api):
    with api.client("mes") as c:
        wait_idle(c)
        r = c.post("/api/v1/job-orders", json=order("SN-API-BOUND"))
        assert r.status_code == 202, r.text
        done = wait_done(c, r.json()["id"])
    assert done["state"] == "complete", done["reason"]
    cycle = done["cycle"]
    assert cycle["lower_bound_s"] > 0 and set(cycle["lower_bound_breakdown"]) == set(BREAKDOWN_KEYS)
    assert cycle["ratio"] == pytest.approx(done["machine_s"] / cycle["lower_bound_s"])


def test_a_stored_cycle_that_json_cannot_carry_is_null_not_a_server_error(api):
    """A ratio to a zero lower bound is NaN; the store keeps it as null (JSON has no NaN:
    PostgreSQL's JSONB refuses one), the API says null.
    An inspection without findings shows an empty list."""
    from station.store import Traceability

    store = api.runtime.store
    iid = store.begin_inspection(PART, serial="SN-NAN", traceability=Traceability())
    store.finish(iid, "aborted", None, "aborted by test", machine_s=1.5,
                 cycle={"machine_s": 1.5, "basis": "measured", "lower_bound_s": 0.0, "ratio": float("nan")})
    with api.client("mes") as c:
        r = c.get(f"/api/v1/inspections/{iid}")
        assert r.status_code == 200, r.text
        body = r.json()
        assert body["machine_s"] == 1.5 and body["cycle"]["ratio"] is None and body["cycle"]["lower_bound_s"] == 0.0
        assert body["findings"] == []
        listed = c.get("/api/v1/inspections", params={"serial": "SN-NAN"})
        assert listed.status_code == 200 and listed.json()["items"][0]["cycle"]["ratio"] is None


def test_retried_order_returns_the_same_job_and_starts_nothing(api):
    key = f"retry-{uuid.uuid4()}"
    with api.client("mes") as c:
        before = c.get("/api/v1/inspections", params={"serial": "SN-IDEM"}).json()["total"]
        first = c.post("/api/v1/job-orders", json=order("SN-IDEM"), headers={"Idempotency-Key": key})
        assert first.status_code == 202, first.text
        again = c.post("/api/v1/job-orders", json=order("SN-IDEM"), headers={"Idempotency-Key": key})
        assert again.status_code == 200, again.text
        assert again.json()["id"] == first.json()["id"]
        wait_done(c, first.json()["id"])
        after_done = c.post("/api/v1/job-orders", json=order("SN-IDEM"), headers={"Idempotency-Key": key})
        assert after_done.status_code == 200 and after_done.json()["id"] == first.json()["id"]
        assert after_done.json()["state"] == "complete"
        assert c.get("/api/v1/inspections", params={"serial": "SN-IDEM"}).json()["total"] == before + 1


def test_second_order_while_busy_is_409(api):
    with api.client("mes") as c:
        wait_idle(c)
        first = c.post("/api/v1/job-orders", json=order("SN-BUSY-1"))
        assert first.status_code == 202
        second = c.post("/api/v1/job-orders", json=order("SN-BUSY-2"))
        assert second.status_code == 409 and "running" in second.json()["detail"]
        wait_done(c, first.json()["id"])
        assert c.get("/api/v1/inspections", params={"serial": "SN-BUSY-2"}).json()["total"] == 0


@pytest.mark.parametrize("body, fragment", [
    ({"part_number": "NO-SUCH-PART", "serial": "S"}, "NO-SUCH-PART"),
    ({"part_number": PART}, "serial"),
    ({"part_number": PART, "serial": "S", "colour": "red"}, "colour"),
    ({"part_number": "../etc/passwd", "serial": "S"}, "part_number"),
])
def test_invalid_orders_are_422_and_say_why(api, body, fragment):
    with api.client("mes") as c:
        r = c.post("/api/v1/job-orders", json=body)
    assert r.status_code == 422
    assert fragment in r.text


def test_unknown_inspection_is_404(api):
    with api.client("mes") as c:
        assert c.get(f"/api/v1/inspections/{uuid.uuid4()}").status_code == 404


def test_filters_and_paging(api):
    with api.client("admin") as c:
        wait_idle(c)
        ids = []
        for i in range(2):
            r = c.post("/api/v1/job-orders", json=order(f"SN-PAGE-{i}", order_id="PO-PAGE"))
            assert r.status_code == 202, r.text
            ids.append(wait_done(c, r.json()["id"])["id"])
        everything = c.get("/api/v1/inspections", params={"limit": 1000}).json()
        assert everything["total"] >= 2 and len(everything["items"]) == everything["total"]
        page1 = c.get("/api/v1/inspections", params={"limit": 1, "offset": 0}).json()
        page2 = c.get("/api/v1/inspections", params={"limit": 1, "offset": 1}).json()
        assert page1["total"] == page2["total"] == everything["total"]
        assert page1["items"][0]["id"] == everything["items"][0]["id"]  # newest first
        assert page2["items"][0]["id"] == everything["items"][1]["id"]
        one = c.get("/api/v1/inspections", params={"serial": "SN-PAGE-1"}).json()
        assert one["total"] == 1 and one["items"][0]["id"] == ids[1]
        assert c.get("/api/v1/inspections", params={"part_number": "OTHER"}).json()["total"] == 0
        passed = c.get("/api/v1/inspections", params={"result": "pass", "limit": 1000}).json()
        assert all(i["result"] == "pass" for i in passed["items"]) and passed["total"] >= 2
        assert c.get("/api/v1/inspections", params={"state": "running"}).json()["total"] == 0
        future = (datetime.now(timezone.utc) + timedelta(hours=1)).isoformat()
        assert c.get("/api/v1/inspections", params={"since": future}).json()["total"] == 0
        assert c.get("/api/v1/inspections", params={"until": future}).json()["total"] == everything["total"]
        assert c.get("/api/v1/inspections", params={"since": "2024-01-01T00:00:00"}).status_code == 422  # no zone
        assert c.get("/api/v1/inspections", params={"result": "maybe"}).status_code == 422
        assert c.get("/api/v1/inspections", params={"limit": 0}).status_code == 422


def test_an_order_sent_the_moment_the_last_inspection_reads_ended_is_taken(api, monkeypatch):
    """A MES polls an inspection until it reads ended and sends the next order at once.
    The station loop still wraps up for a moment after the record is written (here made
    3 s long); the order waits for it instead of being refused with 409 (seen in CI on a
    loaded machine, by ``test_filters_and_paging``)."""
    import asyncio

    session = api.runtime.session
    service_for = session.service_for

    class SlowToWrapUp:
        """The station's inspection service, with 3 s of wrap-up after the record is written."""

        def __init__(self, service):
            self._service = service

        async def inspect(self, *args, **kw):
            outcome = await self._service.inspect(*args, **kw)
            await asyncio.sleep(3.0)
            return outcome

    monkeypatch.setattr(session, "service_for", lambda part: SlowToWrapUp(service_for(part)))
    with api.client("mes") as c:
        wait_idle(c)
        first = c.post("/api/v1/job-orders", json=order("SN-NEXT-0"))
        assert first.status_code == 202, first.text
        assert wait_done(c, first.json()["id"])["state"] == "complete"
        assert c.get("/api/v1/station").json()["busy"]  # still wrapping up: the window is real
        nxt = c.post("/api/v1/job-orders", json=order("SN-NEXT-1"))
        assert nxt.status_code == 202, nxt.text
        assert wait_done(c, nxt.json()["id"])["state"] == "complete"
        wait_idle(c)
