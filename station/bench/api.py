"""``station bench api``: the REST API under a MES's polling load, and what that load
costs the inspection running beside it.

The server is ``station serve`` in its own process on 127.0.0.1 (the simulated
station, a temporary data folder); this process is the clients: ``--clients`` (50)
asyncio tasks, each with its own ``httpx.AsyncClient`` (its own connection), poll
``GET /api/v1/inspections/{id}`` of the running inspection for as long as it runs.

Load model: each client polls once per ``--interval`` (default 0.1 s: 50 clients
offer 500 requests/s, ten times what a MES polling every 1 s would), its requests due
at fixed slots, and a request's latency counts from its due time (a server that falls
behind is charged for the requests it delayed: no coordinated omission).
``--interval 0`` makes the clients poll back to back: a saturation test, where the
latency of 50 closed-loop clients is 50 / throughput whatever the server does.

Per repeat, one inspection runs without load and one with it (alternating, so drift
hits both alike). Reported are medians over the repeats of requests per second,
p50/p99 latency, the slowdown of the loaded inspection (its own start-to-finish time
from the store) against the unloaded one, and whether the result is unchanged: the
same verdicts and every measured value within 5 % of its tolerance of the unloaded one.

Goals: p99 <= 50 ms, slowdown <= 5 %, result unchanged within 5 %. Both processes
share the machine's two cores, so the clients' own CPU counts against the server.
"""

from __future__ import annotations

import asyncio
import contextlib
import os
import ssl
import statistics
import tempfile
import time
from datetime import datetime
from pathlib import Path

import typer

from station.bench import served

PART = "ZDZG-22.2-12.3851"
GOAL_P99_MS = 50.0
GOAL_SLOWDOWN = 0.05


def _duration_s(rec: dict) -> float:
    return (datetime.fromisoformat(rec["finished_at"]) - datetime.fromisoformat(rec["started_at"])).total_seconds()


def _percentile(values: list[float], q: float) -> float:
    s = sorted(values)
    if not s:
        return float("nan")
    k = min(len(s) - 1, max(0, int(round(q * (len(s) - 1)))))
    return s[k]


async def _inspection(url: str, token: str, serial: str, clients: int, interval_s: float = 0.0) -> dict:
    import httpx

    headers = {"Authorization": f"Bearer {token}"}
    # the clients exist before the inspection starts (building 50 of them is the load
    # generator's cost, not the server's), sharing one TLS context (unused on http://)
    tls = ssl.create_default_context()
    async with contextlib.AsyncExitStack() as stack:
        pool = [await stack.enter_async_context(httpx.AsyncClient(base_url=url, headers=headers, timeout=60.0,
                                                                  verify=tls))
                for _ in range(clients + 1)]
        return await _measure(pool, serial, clients, interval_s)


async def _measure(pool, serial: str, clients: int, interval_s: float) -> dict:
    import httpx

    c = pool[-1]
    r = await c.post("/api/v1/job-orders", json={"part_number": PART, "serial": serial})
    r.raise_for_status()
    iid = r.json()["id"]
    path = f"/api/v1/inspections/{iid}"
    latencies: list[float] = []
    errors = [0]
    done = asyncio.Event()

    async def client(k: int) -> None:
        own = pool[k]
        # paced clients start spread over one period; each request is due at its slot
        # and its latency counts from the slot, so a slow server is not excused by the
        # requests it delayed (no coordinated omission)
        due = time.perf_counter() + interval_s * k / max(clients, 1)
        while not done.is_set():
            if interval_s > 0:
                wait = due - time.perf_counter()
                if wait > 0:
                    await asyncio.sleep(wait)
                t0, due = due, due + interval_s
            else:
                t0 = time.perf_counter()
            try:
                resp = await own.get(path)
                ok = resp.status_code == 200
            except httpx.HTTPError:
                ok = False
            if ok:
                latencies.append(time.perf_counter() - t0)
            else:
                errors[0] += 1

    tasks = [asyncio.create_task(client(k)) for k in range(clients)]
    t0 = time.perf_counter()
    while True:  # the watcher: one poll every 0.2 s (the load, if any, runs beside it)
        rec = (await c.get(path)).json()
        if rec["state"] != "running":
            break
        await asyncio.sleep(0.2)
    done.set()
    window = time.perf_counter() - t0
    await asyncio.gather(*tasks)
    out = {"inspection_s": _duration_s(rec), "state": rec["state"], "result": rec["result"],
           "reason": rec.get("reason"),
           "measured": {c["id"]: (c["measured"], c["upper_limit"] - c["lower_limit"])
                        for c in rec.get("characteristics", []) if c.get("measured") is not None}}
    if clients:
        out.update(requests=len(latencies), errors=errors[0], rps=len(latencies) / window,
                   p50_ms=_percentile(latencies, 0.50) * 1e3, p99_ms=_percentile(latencies, 0.99) * 1e3)
    return out


def _recover(url: str, headers: dict) -> None:
    """After a faulted inspection (a drive's watchdog under load): reset and home, so
    the next repeat starts from a ready station."""
    import httpx

    with httpx.Client(base_url=url, headers=headers, timeout=60.0) as c:
        if c.get("/api/v1/station").json()["state"] in ("faulted", "estopped"):
            c.post("/api/v1/station/reset")


def run(repeats: int = 3, clients: int = 50, time_scale: float = 1.0, interval_s: float = 0.1, progress=None) -> dict:
    from station.store import Store
    from station.store.tokens import TokenRepository

    with tempfile.TemporaryDirectory(prefix="bench-api-") as tmp:
        data = Path(tmp)
        with Store(data_dir=data) as store:
            token = TokenRepository(store).create("admin", name="bench")[1]  # reset after a fault too
        server = served.start(data, time_scale=time_scale)
        proc, url = server.proc, server.url
        try:
            # one inspection to warm up (imports, first frames, SQLite pages)
            asyncio.run(_inspection(url, token, "BENCH-WARM", 0))
            quiet, loaded = [], []
            headers = {"Authorization": f"Bearer {token}"}
            for i in range(repeats):
                _recover(url, headers)
                quiet.append(asyncio.run(_inspection(url, token, f"BENCH-Q{i:02d}", 0)))
                if progress:
                    progress()
                _recover(url, headers)
                loaded.append(asyncio.run(_inspection(url, token, f"BENCH-L{i:02d}", clients, interval_s)))
                if progress:
                    progress()
        finally:
            served.stop(proc)

    def med(rows, key):
        values = [r[key] for r in rows if key in r]
        return statistics.median(values) if values else float("nan")

    # the slowdown compares inspections that completed; a faulted one is counted apart
    q_ok = [r for r in quiet if r["state"] == "complete"]
    l_ok = [r for r in loaded if r["state"] == "complete"]
    q_s, l_s = med(q_ok, "inspection_s"), med(l_ok, "inspection_s")
    slowdown = l_s / q_s - 1.0
    p99 = med(loaded, "p99_ms")
    # the result: the same verdicts, and each measured value within 5 % of its tolerance
    # of the unloaded inspection of the same repeat (both carry the frames' own scatter)
    shifts = [abs(lq["measured"][k][0] - qq["measured"][k][0]) / qq["measured"][k][1]
              for qq, lq in zip(quiet, loaded) for k in qq["measured"] if k in lq["measured"]]
    same_verdicts = all(q["result"] == lo["result"] for q, lo in zip(quiet, loaded))
    shift = max(shifts) if shifts else float("nan")
    return {
        "endpoint": "GET /api/v1/inspections/{id} (the running inspection)",
        "clients": clients, "interval_s": interval_s, "offered_rps": clients / interval_s if interval_s > 0 else None,
        "repeats": repeats, "time_scale": time_scale, "cpus": os.cpu_count(),
        "rps_median": med(loaded, "rps"), "p50_ms_median": med(loaded, "p50_ms"), "p99_ms_median": p99,
        "requests_total": sum(r["requests"] for r in loaded), "errors_total": sum(r["errors"] for r in loaded),
        "faulted_quiet": len(quiet) - len(q_ok), "faulted_loaded": len(loaded) - len(l_ok),
        "fault_reasons": sorted({r["reason"] for r in quiet + loaded if r["state"] != "complete"}),
        "inspection_s_median_quiet": q_s, "inspection_s_median_loaded": l_s, "slowdown_median": slowdown,
        "same_verdicts": same_verdicts, "max_result_shift_of_tolerance": shift,
        "goals": {"p99_ms": GOAL_P99_MS, "slowdown": GOAL_SLOWDOWN, "result_shift": GOAL_SLOWDOWN,
                  "result_met": same_verdicts and shift <= GOAL_SLOWDOWN,
                  "p99_met": p99 <= GOAL_P99_MS,
                  "slowdown_met": slowdown <= GOAL_SLOWDOWN and len(l_ok) == len(loaded)},
        "runs": {"quiet": quiet, "loaded": loaded},
    }


def register(bench_app: typer.Typer) -> None:
    from station.cli.common import err_console, out_console, print_json  # the CLI imports this module

    @bench_app.command("api")
    def api_bench(
        repeats: int = typer.Option(3, help="inspections with and without load (each)"),
        clients: int = typer.Option(50, help="concurrent clients polling the running inspection"),
        time_scale: float = typer.Option(1.0, "--time-scale", help="simulated moves run this much faster"),
        interval: float = typer.Option(0.1, "--interval",
                                       help="each client polls once per INTERVAL s (0: back to back, saturation)"),
        json: bool = typer.Option(False, "--json"),
    ) -> None:
        """Requests per second and p99 latency of GET /inspections/{id} under 50 clients, and
        how much that load slows the inspection running beside it (medians over repeats)."""
        if repeats < 1 or clients < 1 or not time_scale > 0:
            raise typer.BadParameter("repeats and clients must be >= 1, the time scale positive")
        from rich.progress import Progress

        with Progress(console=err_console, transient=True) as prog:
            task = prog.add_task("inspections", total=2 * repeats)
            res = run(repeats, clients, time_scale, interval, progress=lambda: prog.advance(task))
        if json:
            print_json(res)
            return
        g = res["goals"]
        out_console.print(
            f"{res['clients']} clients on GET /inspections/{{id}} ({res['cpus']} CPUs shared with the server): "
            f"{res['rps_median']:.0f} requests/s, p50 {res['p50_ms_median']:.1f} ms, "
            f"p99 {res['p99_ms_median']:.1f} ms (goal <= {g['p99_ms']:.0f}: {'met' if g['p99_met'] else 'MISSED'}); "
            f"{res['errors_total']} errors", highlight=False)
        out_console.print(
            f"inspection {res['inspection_s_median_quiet']:.2f} s without load, {res['inspection_s_median_loaded']:.2f} s "
            f"with it: slowdown {res['slowdown_median'] * 100:+.1f} % (goal <= {g['slowdown'] * 100:.0f} %: "
            f"{'met' if g['slowdown_met'] else 'MISSED'}); medians of {res['repeats']} repeats", highlight=False)
        out_console.print(
            f"results: verdicts {'the same' if res['same_verdicts'] else 'DIFFERENT'}; largest change of a "
            f"measured value {res['max_result_shift_of_tolerance'] * 100:.1f} % of its tolerance (goal <= "
            f"{g['result_shift'] * 100:.0f} %: {'met' if g['result_met'] else 'MISSED'})", highlight=False)
        if res["faulted_loaded"] or res["faulted_quiet"]:
            out_console.print(f"FAULTED: {res['faulted_loaded']} loaded and {res['faulted_quiet']} quiet inspections: "
                              + "; ".join(res["fault_reasons"]), highlight=False)
