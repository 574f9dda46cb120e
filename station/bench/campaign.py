"""``station campaign``: a production campaign on a scenario's world with the station's own model.

Parts are inspected one after another on the twins; every ``master_every`` parts the
certified master is put on the table (into the twin's world: ``sim.masters``) and
checked. The station's charts watch every inspection and check (docs/monitor.md); the
campaign reports, per inspection, the worst |measured - truth| over the part's
positions and diameters and the largest U the station stated, the alarms with the
inspection after which each was raised, and the models the station used.

The twins' motion runs ``time_scale`` times faster than real time, and the world's
drift (heat, air, wear: sim.drift) runs on the drives' clock, so a campaign's physics
see about as many seconds per part as the machine would take (a part takes about 7 s
of machine time and 1.5-2 s of this PC's time: a time scale near 4 keeps the clocks
within a factor of two of each other).
"""

from __future__ import annotations

import asyncio
import statistics
import tempfile
import time
from pathlib import Path

MASTER = "MC-22.2-A"


def worst_error_um(outcome) -> float | None:
    errs = [abs(c.measured - c.true_value) * 1e3 for c in outcome.characteristics
            if c.measured is not None and c.true_value is not None]
    return max(errs) if errs else None


def largest_u_um(outcome) -> float | None:
    us = [c.uncertainty_k2 * 1e3 for c in outcome.characteristics if c.uncertainty_k2 is not None]
    return max(us) if us else None


async def _campaign(scenario: Path | None, parts: int, master_every: int, data: Path, time_scale: float,
                    seed: int, auto_approve: bool = False, progress=None) -> dict:
    from station.checks.master import load_master
    from station.runtime import open_session
    from station.parts import load_part
    from station.sequencer.engine import link_fault

    cert = load_master(MASTER)
    family = load_part(cert.part_number)
    inspections, alarms, checks, link_faults = [], [], [], []
    t0 = time.perf_counter()
    async with open_session(scenario=scenario, time_scale=time_scale, data_dir=data) as s:
        models = [{"index": 1, "version": s.model_version, "added": []}]
        proposals = []

        async def _proposed(i: int, p) -> None:
            proposals.append({"index": i, "id": p.id, "changes": [c.term for c in p.changes],
                              "kind": p.explanation.get("kind"), "expected_change_um": p.expected_change_um})
            if auto_approve:  # standing in for the engineer
                await s.decide(p.id, True, "campaign --auto-approve")
                models.append({"index": i + 1, "version": s.model_version, "added": [c.term for c in p.changes]})

        for i in range(1, parts + 1):
            out = await s.inspect(family, f"CAMPAIGN-{seed}-{i:04d}")
            if out.state == "faulted" and link_fault(s.engine):
                # as the plant's MES does: a part whose inspection a link fault stopped
                # (a drive's watchdog) is sent again, once; the fault stays in the output
                link_faults.append({"index": i, "reason": out.reason})
                out = await s.inspect(family, f"CAMPAIGN-{seed}-{i:04d}")
            inspections.append({"index": i, "state": out.state, "result": out.result, "reason": out.reason,
                                "worst_error_um": worst_error_um(out), "u_um": largest_u_um(out),
                                "model_version": s.model_version,
                                "machine_s": None if out.cycle is None else out.cycle["machine_s"]})
            alarms += [{"index": i, "reason": a.reason, "chart": a.chart} for a in out.alarms]
            if any(a.chart == "grating" for a in out.alarms):
                # the grating departs from the model's carriage: the station checks Z against
                # its grating by itself (no master needed) and proposes what its model lacks
                ax = await s.check_axis(family, propose=True, plots=False)
                checks.append({"index": i, "kind": "axis", "verdict": ax.verdict, "machine_s": ax.machine_s,
                               "effects": [e["name"] for e in (ax.report or {}).get("effects", [])]})
                if ax.proposal is not None:
                    await _proposed(i, ax.proposal)
            # the campaign plays the plant: the master goes on every K parts, and at once
            # when the station asks for a check (the MES reads "station needs a check")
            if master_every and (i % master_every == 0 or out.alarms):
                chk = await s.check_master(cert, family, seed=seed)
                checks.append({"index": i, "kind": "master", "in_control": chk.in_control,
                               "z": [c.z for c in chk.checks if c.id.endswith(".position")],
                               "worst_error_um": worst_error_um(chk.inspection)})
                alarms += [{"index": i, "reason": a.reason, "chart": a.chart} for a in chk.alarms]
                if chk.alarms:
                    holes_mm = {h.id: h.position_mm for h in cert.holes}
                    p = await s.propose(chk.alarms[0].reason, holes_mm)
                    if p is not None:
                        await _proposed(i, p)
            if progress:
                progress()
        state = s.watch.state()
    wall = time.perf_counter() - t0
    machine = [r["machine_s"] for r in inspections if r["machine_s"] is not None]
    return {"scenario": str(scenario) if scenario else "default", "parts": parts, "master_every": master_every,
            "seed": seed, "time_scale": time_scale, "inspections": inspections, "alarms": alarms,
            "models": models, "checks": checks, "proposals": proposals, "watch": state, "link_faults": link_faults,
            "cost": {"wall_s_per_inspection": wall / max(1, parts + len(checks)),
                     "machine_s_per_inspection_median": statistics.median(machine) if machine else None}}


def run_campaign(scenario: Path | None = None, parts: int = 20, master_every: int = 0, data: Path | None = None,
                 time_scale: float = 4.0, seed: int = 0, progress=None, auto_approve: bool = False) -> dict:
    if parts < 1:
        raise ValueError("a campaign needs at least one part")
    if master_every < 0:
        raise ValueError("--master-every must be 0 (never) or a positive number of parts")
    if data is not None:
        return asyncio.run(_campaign(scenario, parts, master_every, data, time_scale, seed, auto_approve, progress))
    with tempfile.TemporaryDirectory() as tmp:
        return asyncio.run(_campaign(scenario, parts, master_every, Path(tmp), time_scale, seed, auto_approve, progress))
