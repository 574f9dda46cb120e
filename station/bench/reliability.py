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
* **fuzzing** -- ``tests/reliability/test_fuzz.py``'s targets with many more examples.

The machinery (the session in a thread, the fault injector, the crash child, the fuzz
targets and their fakes) is the test kit's (``testkit``), so that the bench and the
tests try the same thing and the product carries none of it; this module runs the
three parts at full counts and reports.
"""

from __future__ import annotations

import tempfile
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any, Callable

if TYPE_CHECKING:
    from testkit.matrix import CellResult

# the test kit is imported where it is used: ``station --help`` and every other
# command register this bench without loading it

#: longest one cell (its inspection and the next one) may take in the bench
CELL_TIMEOUT_S = 240.0
#: the crash trials' seed in the bench (``make test`` uses another: docs/reliability.md)
CRASH_SEED = 2024


# ---------------------------------------------------------------------------- fuzzing


def run_fuzz(max_examples: int, seed: int = 0) -> dict[str, dict]:
    """Every target with ``max_examples`` per seed text; inputs tried and failures per target."""
    from hypothesis import HealthCheck, given, settings, seed as hseed

    from testkit.fuzz import fuzz_one, fuzz_targets, modbus_scripts, modbus_target, mutated_text

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


# ---------------------------------------------------------------------------- fault matrix


def run_matrix(repeats: int = 1, log: Callable[[str], None] | None = None, only: str = "") -> list[CellResult]:
    """Every cell ``repeats`` times, one session per fault kind (shared by its cells)."""
    from station.parts import load_part
    from testkit.cells import matrix_cells
    from testkit.matrix import CellResult, run_cell
    from testkit.session import PART, SessionThread

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
                        r = st.run(lambda s: run_cell(s, spec, cell, serial=f"SN-{cell.id}-{k}"),
                                   timeout=CELL_TIMEOUT_S)
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
        cells: str = typer.Option("", help="only the matrix cells whose id contains this (e.g. delay-moving)"),
    ):
        """Fault matrix, crash safety (SIGKILL) and fuzzing at full counts."""
        wanted = {p.strip() for p in parts.split(",")}
        say = (lambda msg: err_console.print(msg, markup=False, highlight=False))
        doc: dict[str, Any] = {}
        bad = False
        if "matrix" in wanted:
            t0 = time.perf_counter()
            res = run_matrix(repeats, log=say, only=cells)
            rows = [r.to_json() for r in res]
            bad |= any(r["problems"] for r in rows)
            doc["matrix"] = {"cells": len({r["cell"] for r in rows}), "runs": len(rows),
                             "with_problems": sorted({r["cell"] for r in rows if r["problems"]}),
                             "wall_s": round(time.perf_counter() - t0, 1),
                             "results": [{k: r[k] for k in ("cell", "state", "result", "reason", "retries",
                                                            "next_state", "next_result", "problems")} for r in rows]}
        if "crash" in wanted:
            from testkit.crash import crash_trials

            t0 = time.perf_counter()
            with tempfile.TemporaryDirectory(prefix="crash-") as d:
                rep = crash_trials(kills, d, seed=CRASH_SEED, log=say)
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
