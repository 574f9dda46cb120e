"""End-to-end inspections on the simulated station, through the real drivers.

Every test runs the twins on 127.0.0.1 (Modbus TCP, the encoder on a pty, the camera
twin in-process) with motion time scaled, and a store in a temporary folder.
"""

from __future__ import annotations

import asyncio
import os
import signal
import subprocess
import sys
import textwrap
import time
from dataclasses import replace
from pathlib import Path

import pytest

from sim.faults import FaultKind
from sim.world import HoleTruth, PartTruth, World
from station.runtime import open_session
from station.parts import load_part
from station.sequencer.engine import State
from station.store import Store

PART = "ZDZG-22.2-12.3851"
TIME_SCALE = 50.0


@pytest.fixture(scope="module")
def spec():
    return load_part(PART)


def run(coro):
    return asyncio.run(asyncio.wait_for(coro, timeout=240))


def test_good_part_passes_and_is_stored(spec, tmp_path):
    async def go():
        async with open_session(time_scale=TIME_SCALE, data_dir=tmp_path) as s:
            return await s.inspect(spec, "SN-PASS")

    out = run(go())
    assert out.state == "complete" and out.result == "pass", out.reason
    for c in out.characteristics:
        assert c.passed and c.true_value is not None
        assert abs(c.measured - c.true_value) <= 3e-3, c.id  # 3 um, the bar
        assert 0 < c.uncertainty_k2 < 5e-3
    with Store(data_dir=tmp_path) as store:
        rec = store.get(out.id)
        assert rec.state == "complete" and rec.result == "pass"
        assert len(rec.characteristics) == 4 and len(rec.images) == 2
        assert rec.traceability["mode"] == "simulated" and rec.traceability["config_hash"]
        assert len(rec.traceability["model_fingerprint"]) == 16 and rec.traceability["camera_mm_per_px"] == 0.01
        for img in rec.images:
            assert store.image_path(img).is_file()
        # the part's angular datum, set by hole_1's survey, is a finding of the record
        assert [(f.kind, f.subject) for f in rec.findings] == [("datum", "hole_1")]
        # the machine time at the axes' real speeds, not the twin's 50x: at least the
        # bound of the same plan, and more than the run's whole wall time at the twin's
        # speed-up could have spent on moves (a load-free bound: the wall time follows the
        # machine's load, which a CI run beside another stream doubled)
        cyc = rec.cycle
        assert rec.machine_s == cyc["machine_s"] == pytest.approx(sum(cyc["breakdown"].values()))
        assert cyc["basis"] == "modelled"
        assert cyc["lower_bound_s"] <= rec.machine_s
        wall_s = (rec.finished_at - rec.started_at).total_seconds()
        assert cyc["breakdown"]["moves_s"] > wall_s / TIME_SCALE
        assert cyc["breakdown"]["moves_s"] >= 360.0 / 90.0  # the survey turns the table a whole turn (90 deg/s)
        assert cyc["breakdown"]["frames_s"] == pytest.approx(out.cycle["breakdown"]["frames_s"])


def test_part_with_a_hole_out_of_tolerance_fails(spec, tmp_path):
    bad = World(part=PartTruth(holes=(HoleTruth("hole_1", 71.03, 0.0, 0.70), HoleTruth("hole_2", 85.32, 0.0, 0.70))))

    async def go():
        async with open_session(time_scale=TIME_SCALE, data_dir=tmp_path, world=bad) as s:
            return await s.inspect(spec, "SN-FAIL")

    out = run(go())
    assert out.state == "complete" and out.result == "fail"
    verdict = {c.id: c.passed for c in out.characteristics}
    assert verdict == {"hole_1.diameter": True, "hole_1.position": True, "hole_2.diameter": True, "hole_2.position": False}
    pos2 = next(c for c in out.characteristics if c.id == "hole_2.position")
    assert abs(pos2.measured - 85.32) < 3e-3  # found by the coarse search, measured right
    assert "hole_2.position" in out.reason


def test_pause_and_resume(spec, tmp_path):
    async def go():
        async with open_session(time_scale=TIME_SCALE, data_dir=tmp_path) as s:
            progress = []
            s.engine.subscribe(lambda ev: progress.append(ev.data.get("done")) if ev.kind == "progress" else None)
            task = asyncio.create_task(s.inspect(spec, "SN-PAUSE"))
            while not progress:
                await asyncio.sleep(0.01)
            s.engine.pause()
            for _ in range(3000):
                if s.engine.state == State.PAUSED:
                    break
                await asyncio.sleep(0.01)
            paused = s.engine.state
            n_at_pause = len(progress)
            await asyncio.sleep(0.5)
            n_after_wait = len(progress)
            s.engine.resume()
            out = await task
            return paused, n_at_pause, n_after_wait, out

    paused, n_at_pause, n_after_wait, out = run(go())
    assert paused == State.PAUSED
    assert n_after_wait == n_at_pause  # nothing moves while paused
    assert out.result == "pass"


def test_abort_mid_scan_then_next_inspection_runs(spec, tmp_path):
    async def go():
        async with open_session(time_scale=TIME_SCALE, data_dir=tmp_path) as s:
            task = asyncio.create_task(s.inspect(spec, "SN-ABORT"))
            while s.engine.progress[0] < 2:
                await asyncio.sleep(0.01)
            s.engine.abort("operator pressed abort")
            aborted = await task
            z_moving = (await s.station.z.status()).moving
            again = await s.inspect(spec, "SN-AFTER")
            return aborted, z_moving, again

    aborted, z_moving, again = run(go())
    assert aborted.state == "aborted" and "operator" in aborted.reason
    assert not z_moving
    assert again.result == "pass"
    with Store(data_dir=tmp_path) as store:
        assert store.get(aborted.id).state == "aborted"


def test_drive_fault_mid_scan_is_recorded_and_cleared(spec, tmp_path):
    async def go():
        async with open_session(time_scale=TIME_SCALE, data_dir=tmp_path) as s:
            drive = s.station.twins.station.drives["Z"]
            task = asyncio.create_task(s.inspect(spec, "SN-FAULT"))
            while s.engine.progress[0] < 2:
                await asyncio.sleep(0.01)
            s.station.twins.call(lambda: drive.faults.activate(FaultKind.DRIVE_FAULT, code=0x20))
            faulted = await task
            state_after = s.engine.state
            s.station.twins.call(lambda: drive.faults.clear())
            again = await s.inspect(spec, "SN-RECOVERED")
            return faulted, state_after, again

    faulted, state_after, again = run(go())
    assert faulted.state == "faulted"
    assert faulted.reason == "DriveFault: Z: drive fault 0x0020: motor overcurrent"
    assert state_after == State.FAULTED
    assert again.result == "pass"  # reset and homed again, without a restart


CRASH_SCRIPT = textwrap.dedent(
    """
    import asyncio, sys
    from station.runtime import open_session
    from station.parts import load_part

    async def main():
        async with open_session(time_scale=2.0, data_dir=sys.argv[1]) as s:
            s.engine.subscribe(lambda ev: print("progress", flush=True) if ev.kind == "progress" else None)
            await s.inspect(load_part("ZDZG-22.2-12.3851"), "SN-CRASH")
    asyncio.run(main())
    """
)


def test_crash_mid_inspection_is_found_interrupted(tmp_path):
    proc = subprocess.Popen([sys.executable, "-c", CRASH_SCRIPT, str(tmp_path)], stdout=subprocess.PIPE, text=True)
    try:
        line = proc.stdout.readline()  # the scan is under way
        assert line.startswith("progress")
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    store = Store.open(data_dir=tmp_path)
    try:
        recs = store.list_inspections()
        assert len(recs) == 1
        assert recs[0].state == "interrupted" and recs[0].serial == "SN-CRASH"
        with store.engine.connect() as conn:
            assert conn.exec_driver_sql("PRAGMA integrity_check").scalar() == "ok"
    finally:
        store.close()
