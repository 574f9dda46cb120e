"""Crash safety: SIGKILL an inspecting process at random moments, then check the store.

:func:`crash_trials` starts ``python -m testkit.crash_child`` (inspections back to
back), kills it after a random delay, opens the store as the station opens it (lock,
migrate, recover) and checks it with :func:`check_store` (docs/reliability.md,
section 2).
"""

from __future__ import annotations

import dataclasses
import os
import random
import signal
import subprocess
import sys
import threading
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

from testkit.matrix import CHARACTERISTICS, TRUTH_TOLERANCE_MM

#: the child program, run as a module of this package
CHILD_MODULE = "testkit.crash_child"


def child_environment() -> dict[str, str]:
    """The child's environment: unbuffered output (an id printed is an id sent), and
    the folder this test kit was imported from first on its path, so the child finds
    ``testkit`` wherever the parent did (an installed package, or a source tree)."""
    root = str(Path(__file__).resolve().parents[1])
    path = os.environ.get("PYTHONPATH", "")
    return dict(os.environ, PYTHONUNBUFFERED="1", PYTHONPATH=root + (os.pathsep + path if path else ""))


@dataclass
class CrashReport:
    """What the kills left: counts over the store after the last kill."""

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
                if len(chars) != CHARACTERISTICS:
                    problems.append(f"{rec.id} complete with {len(chars)} characteristics")
                passed = all(c.passed for c in chars)
                if (rec.result == "pass") != passed:
                    problems.append(f"{rec.id} result {rec.result} but characteristics passed={passed}")
                for c in chars:
                    if c.measured is None or c.true_value is None or abs(c.measured - c.true_value) > TRUTH_TOLERANCE_MM:
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

    About one kill in four lands in the child's start-up (0.3-3 s after it was started:
    imports, the store's migration and recovery, the twins); the others a random 0.3 s to
    ``max_delay_s`` after the child said it was ready, among its homing, scans and
    commits. Timed from "ready", the kills hit inspections however long a loaded
    machine takes to start a Python process. Every fourth trial (the third, seventh,
    ...; never in start-up) is timed from the child's first commit instead (its first
    ``done``): whatever pace a loaded machine sets, some results are acknowledged before
    a kill, and that kill lands in the next inspection (a CI run on two busy cores took
    over 8.8 s an inspection, and no kill timed from "ready" came after a commit)."""
    rng = random.Random(seed)
    data_dir = Path(data_dir)
    rep = CrashReport()
    acknowledged: dict[str, str] = {}
    env = child_environment()
    for trial in range(n):
        in_startup = rng.random() < 0.25
        delay = rng.uniform(0.3, 3.0) if in_startup else rng.uniform(0.3, max_delay_s)
        after_commit = trial % 4 == 2
        if after_commit and in_startup:
            delay = rng.uniform(0.3, max_delay_s)
        in_startup = in_startup and not after_commit
        args = [str(data_dir), str(per_child), f"K{trial:03d}"] + ([db_url] if db_url else [])
        proc = subprocess.Popen([sys.executable, "-m", CHILD_MODULE, *args],
                                stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True, env=env)
        lines: list[str] = []
        ready = threading.Event()
        committed = threading.Event()

        def read(proc=proc, lines=lines, ready=ready, committed=committed):
            for line in iter(proc.stdout.readline, ""):
                lines.append(line)
                if line.startswith("ready"):
                    ready.set()
                elif line.startswith("done"):
                    committed.set()
            # the child ended (or was killed): nobody waits for what never comes
            ready.set()
            committed.set()

        reader = threading.Thread(target=read, daemon=True)
        reader.start()
        try:
            if not in_startup:
                ready.wait(timeout=READY_TIMEOUT_S)
            if after_commit:
                committed.wait(timeout=READY_TIMEOUT_S)
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
            since = "its first commit" if after_commit else "start-up" if in_startup else "ready"
            log(f"kill {trial + 1}/{n} {delay:.2f} s after {since}: {len(acknowledged)} acknowledged, {counts}")
    rep.acknowledged = len(acknowledged)
    rep.inspections = counts["inspections"]
    rep.complete = counts.get("complete", 0)
    rep.interrupted = counts.get("interrupted", 0)
    rep.faulted = counts.get("faulted", 0)
    return rep
