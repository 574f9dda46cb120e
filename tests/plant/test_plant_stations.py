"""A plant: three simulated stations (`station serve` processes) write one PostgreSQL
database at once; each is SIGKILLed once in the middle of an inspection and started
again. An MES thread per station orders 30 inspections with Idempotency-Keys, as a
plant MES does, and retries an order whose answer it did not get.

Checked on the database afterwards:

* nothing lost: every inspection an MES saw finished is stored, finished the same way;
* nothing duplicated: one inspection per Idempotency-Key, one complete inspection per
  serial, 30 per station;
* every interrupted one is marked (state ``interrupted``, a reason), and only the
  killed station's own: a restart never cuts off another station's running inspection;
* every record and every event carries its station's id, and the API's ``?station=``
  filter of any station serves each station's records.

Runs on the test run's own PostgreSQL cluster (tests/pgcluster.py) whatever ``--db``.
"""

from __future__ import annotations

import os
import signal
import threading
import time
from collections import Counter
from pathlib import Path

import httpx
import pytest

from station.bench import served as srv
from station.store import Store
from station.store.tokens import TokenRepository

PART = "ZDZG-22.2-12.3851"
STATIONS = ("line1-st1", "line1-st2", "line2-st1")
PER_STATION = 30
#: simulated moves this much faster than real time: the PC's vision work dominates
TIME_SCALE = 100.0
#: an inspection that takes longer than this is hung
INSPECTION_TIMEOUT_S = 180.0


class StationRun:
    """One station and its MES: order, poll, kill once, restart, retry."""

    def __init__(self, station_id: str, data: Path, db_url: str, token: str, kill_at: int) -> None:
        self.station_id = station_id
        self.data = data
        self.db_url = db_url
        self.headers = {"Authorization": f"Bearer {token}"}
        self.kill_at = kill_at
        self.served: srv.Served | None = None
        #: what the MES saw finished: inspection id -> state
        self.seen_final: dict[str, str] = {}
        #: inspections the MES saw running when the station was killed
        self.killed_running: list[str] = []
        self.keys: list[str] = []
        self.error: BaseException | None = None

    def start(self) -> None:
        self.served = srv.start(self.data, time_scale=TIME_SCALE,
                                extra=["--db", self.db_url, "--station-id", self.station_id])

    def client(self) -> httpx.Client:
        return httpx.Client(base_url=self.served.url, headers=self.headers, timeout=httpx.Timeout(30.0))

    def order(self, serial: str, key: str) -> dict:
        """POST a job order; on a 409 (the station still busy after a restart) wait and retry."""
        deadline = time.monotonic() + INSPECTION_TIMEOUT_S
        while True:
            with self.client() as c:
                r = c.post("/api/v1/job-orders", json={"part_number": PART, "serial": serial},
                           headers={"Idempotency-Key": key})
            if r.status_code in (200, 202):
                return r.json()
            if r.status_code != 409 or time.monotonic() > deadline:
                raise AssertionError(f"{self.station_id}: job order {key}: {r.status_code} {r.text}")
            time.sleep(0.3)

    def wait_final(self, inspection_id: str) -> dict:
        deadline = time.monotonic() + INSPECTION_TIMEOUT_S
        with self.client() as c:
            while True:
                body = c.get(f"/api/v1/inspections/{inspection_id}").raise_for_status().json()
                if body["state"] != "running":
                    return body
                if time.monotonic() > deadline:
                    raise AssertionError(f"{self.station_id}: {inspection_id} still running")
                time.sleep(0.2)

    def kill_and_restart(self) -> None:
        os.kill(self.served.proc.pid, signal.SIGKILL)
        self.served.proc.wait(timeout=30)
        self.start()

    def run(self) -> None:
        try:
            done = 0
            attempt = 0
            while done < PER_STATION:
                serial = f"{self.station_id}-{done:02d}"
                key = f"{self.station_id}/{serial}/{attempt}"
                self.keys.append(key)
                job = self.order(serial, key)
                if attempt == 0 and done == self.kill_at:
                    # the MES has the 202; the station dies before it can answer the poll
                    time.sleep(0.5)
                    with self.client() as c:
                        state = c.get(f"/api/v1/inspections/{job['id']}").json()["state"]
                    assert state == "running", f"{self.station_id}: the kill would not land mid-inspection"
                    self.killed_running.append(job["id"])
                    self.kill_and_restart()
                    # the MES retries the order it lost track of: the same key answers with
                    # the same inspection, which the restarted station has marked
                    again = self.order(serial, key)
                    assert again["id"] == job["id"]
                    assert again["state"] == "interrupted", again
                    self.seen_final[job["id"]] = "interrupted"
                    attempt += 1
                    continue
                final = self.wait_final(job["id"])
                self.seen_final[job["id"]] = final["state"]
                assert final["state"] == "complete", f"{self.station_id}: {final['state']}: {final.get('reason')}"
                done += 1
                attempt = 0
        except BaseException as exc:  # noqa: BLE001 - reported by the test's thread join
            self.error = exc


@pytest.mark.timeout(1500)
def test_three_stations_one_database_with_sigkills(tmp_path, pg_cluster):
    db_url = pg_cluster.database("plant", empty=True)  # a new plant database: no schema yet
    runs = [StationRun(sid, tmp_path / sid, db_url, "", kill_at=k)
            for sid, k in zip(STATIONS, (7, 15, 23))]
    for run in runs:
        run.data.mkdir()
    try:
        # started at once on the empty database: they migrate it once between them and
        # take their station locks concurrently
        starters = [threading.Thread(target=run.start) for run in runs]
        for t in starters:
            t.start()
        for t in starters:
            t.join(timeout=240)
        assert all(run.served is not None for run in runs), "a station did not start"
        with Store(db_url, data_dir=tmp_path / "admin") as store:
            _, token = TokenRepository(store).create("mes", name="plant MES")  # one MES token, every station
        for run in runs:
            run.headers = {"Authorization": f"Bearer {token}"}
        threads = [threading.Thread(target=run.run, name=run.station_id) for run in runs]
        for t in threads:
            t.start()
        for t in threads:
            t.join(timeout=1400)
        for run in runs:
            if run.error is not None:
                raise AssertionError(f"{run.station_id}: {run.error}\n{run.served.log_tail}") from run.error

        # the API of any station serves every station's records, filtered by ?station=
        with runs[0].client() as c:
            stations = c.get("/api/v1/stations").json()
            assert stations["this"] == STATIONS[0] and stations["stations"] == sorted(STATIONS)
            for run in runs:
                page = c.get("/api/v1/inspections", params={"station": run.station_id, "limit": 1000}).json()
                assert page["total"] == PER_STATION + 1
                assert {i["id"] for i in page["items"]} == set(run.seen_final)
                assert {i["station_id"] for i in page["items"]} == {run.station_id}
    finally:
        for run in runs:
            if run.served is not None:
                srv.stop(run.served.proc)

    with Store(db_url, data_dir=tmp_path / "admin") as store:
        everything = store.list_inspections(limit=1000)
        assert len(everything) == store.count_inspections() == len(STATIONS) * (PER_STATION + 1)
        for run in runs:
            mine = [store.get(s.id) for s in everything if s.station_id == run.station_id]
            # nothing lost: every inspection the MES saw finished is stored, finished the same way
            assert {r.id: r.state for r in mine} == run.seen_final
            # nothing duplicated: one inspection per key, one complete per serial
            keys = Counter(r.idempotency_key for r in mine)
            assert sorted(keys) == sorted(run.keys) and set(keys.values()) == {1}
            complete = Counter(r.serial for r in mine if r.state == "complete")
            assert len(complete) == PER_STATION and set(complete.values()) == {1}
            # every interrupted one marked, and it is the one killed on this station
            interrupted = [r for r in mine if r.state == "interrupted"]
            assert [r.id for r in interrupted] == run.killed_running
            assert all(r.reason and "stopped before the inspection finished" in r.reason for r in interrupted)
            assert all(r.result in ("pass", "fail") and len(r.characteristics) == 4
                       for r in mine if r.state == "complete")
            # the events of this station's inspections carry its id
            for r in (interrupted[0], next(r for r in mine if r.state == "complete")):
                events = store.events(r.id)
                assert events and {e.station_id for e in events} == {run.station_id}
        assert not [s for s in everything if s.state == "running"]
