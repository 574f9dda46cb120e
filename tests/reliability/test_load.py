"""Fifty clients polling a running inspection through the served station: every
answer is a 200 with a consistent record (never an older state after a newer one,
never a finished record without its characteristics), the inspection completes with
the same verdict as without load, and the final record is the store's.

Latency and slowdown are figures of `station bench api`, not asserted here.
"""

from __future__ import annotations

import asyncio
import ssl

import httpx

from station.bench import served
from station.store import Store
from station.store.tokens import TokenRepository

PART = "ZDZG-22.2-12.3851"
ORDER = {"running": 0, "complete": 1}


async def _inspect_under_load(url: str, token: str, serial: str, clients: int) -> tuple[dict, list[list[dict]]]:
    headers = {"Authorization": f"Bearer {token}"}
    tls = ssl.create_default_context()
    pool = [httpx.AsyncClient(base_url=url, headers=headers, timeout=30.0, verify=tls) for _ in range(clients + 1)]
    try:
        r = await pool[-1].post("/api/v1/job-orders", json={"part_number": PART, "serial": serial})
        assert r.status_code == 202, r.text
        path = f"/api/v1/inspections/{r.json()['id']}"
        seen: list[list[dict]] = [[] for _ in range(clients)]
        bad: list[str] = []
        done = asyncio.Event()

        async def client(k: int) -> None:
            while not done.is_set():
                resp = await pool[k].get(path)
                if resp.status_code != 200:
                    bad.append(f"{resp.status_code}: {resp.text[:200]}")
                else:
                    seen[k].append(resp.json())
                await asyncio.sleep(0.1)

        tasks = [asyncio.create_task(client(k)) for k in range(clients)]
        while (rec := (await pool[-1].get(path)).json())["state"] == "running":
            await asyncio.sleep(0.2)
        await asyncio.sleep(0.3)  # a few polls of the finished record too
        done.set()
        await asyncio.gather(*tasks)
        assert not bad, bad[:5]
        return rec, seen
    finally:
        for c in pool:
            await c.aclose()


def test_fifty_polling_clients_see_a_consistent_record_and_change_nothing(tmp_path, db_url):
    url = db_url(tmp_path)  # the served station's database (a child process: given explicitly)
    with Store(url, data_dir=tmp_path) as store:
        token = TokenRepository(store).create("mes", name="load")[1]
    with served.served(tmp_path, time_scale=20.0, extra=["--db", url]) as server:
        quiet = asyncio.run(_inspect_under_load(server.url, token, "LOAD-Q", 0))[0]
        final, per_client = asyncio.run(_inspect_under_load(server.url, token, "LOAD-L", 50))
    assert quiet["state"] == final["state"] == "complete"
    assert final["result"] == quiet["result"] == "pass"
    answers = [a for seen in per_client for a in seen]
    assert all(per_client) and len(answers) >= 100
    # per client, the state never goes back; a finished answer always carries its results
    for seen in per_client:
        states = [ORDER[a["state"]] for a in seen]
        assert states == sorted(states), "a client saw an older state after a newer one"
    for a in answers:
        assert a["id"] == final["id"]
        if a["state"] == "complete":
            assert a == final, "a complete record differs from the final one"
        else:
            assert a["state"] == "running" and a["result"] is None
    assert any(a["state"] == "running" for a in answers) and any(a["state"] == "complete" for a in answers)
    # the record the API served last is the one in the store
    with Store(url, data_dir=tmp_path, migrate=False) as store:
        rec = store.get(final["id"])
    assert rec.result == final["result"] and len(rec.characteristics) == len(final["characteristics"])
    assert [c.measured for c in rec.characteristics] == [c["measured"] for c in final["characteristics"]]
