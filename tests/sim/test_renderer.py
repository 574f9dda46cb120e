"""The camera twin's renderer process: the same pixels as in-process, and a lost
worker does not lose the camera."""

from __future__ import annotations

import asyncio
import os
import signal
from collections import OrderedDict

import numpy as np
import pytest

from sim.camera.render import HoleSpec
from sim.camera.renderer import RendererLost, RendererProcess, render_image
from sim.camera.twin import small_optics

PARAMS = small_optics().params
SPECS = [HoleSpec(160.3, 128.7, 40.0)]


def test_the_worker_renders_what_the_thread_renders():
    async def go():
        r = RendererProcess()
        await r.start()
        try:
            return await r.render(PARAMS, SPECS, 11, (5, 7), 99), await r.render(PARAMS, SPECS, 12, (5, 7), 99)
        finally:
            r.stop()

    a, b = asyncio.run(go())
    walls: OrderedDict = OrderedDict()
    np.testing.assert_array_equal(a, render_image(PARAMS, SPECS, 11, (5, 7), 99, walls))
    np.testing.assert_array_equal(b, render_image(PARAMS, SPECS, 12, (5, 7), 99, walls))
    assert not np.array_equal(a, b)  # new sensor noise on the same wall


def test_a_dead_worker_is_reported_and_stopped():
    async def go():
        r = RendererProcess()
        await r.start()
        pid = r.pid
        assert pid is not None
        os.kill(pid, signal.SIGKILL)
        with pytest.raises(RendererLost, match="died"):
            for _ in range(50):  # the pool notices the death within a few calls
                await r.render(PARAMS, SPECS, 1, (0, 0), 1)
                await asyncio.sleep(0.05)
        with pytest.raises(RendererLost, match="stopped"):
            await r.render(PARAMS, SPECS, 1, (0, 0), 1)

    asyncio.run(go())


OWNER = """
import asyncio, sys, time
from sim.camera.renderer import RendererProcess
async def main():
    r = RendererProcess()
    await r.start()
    print(r.pid, flush=True)
    time.sleep(60)
asyncio.run(main())
"""


def _alive(pid: int) -> bool:
    try:
        with open(f"/proc/{pid}/stat") as f:
            return f.read().split(")")[1].split()[0] != "Z"
    except FileNotFoundError:
        return False


def test_a_worker_ends_itself_when_its_station_is_killed_outright():
    import subprocess
    import sys
    import time

    owner = subprocess.Popen([sys.executable, "-c", OWNER], stdout=subprocess.PIPE, text=True)
    try:
        worker = int(owner.stdout.readline())
        assert _alive(worker)
        owner.kill()  # SIGKILL: no clean shutdown of the pool
        owner.wait(timeout=10)
        deadline = time.monotonic() + 5.0
        while _alive(worker) and time.monotonic() < deadline:
            time.sleep(0.1)
        assert not _alive(worker), "the renderer worker outlived its station"
    finally:
        if owner.poll() is None:
            owner.kill()
            owner.wait(timeout=10)


def _rss_kb(pid: int) -> int:
    with open(f"/proc/{pid}/status") as f:
        return next(int(line.split()[1]) for line in f if line.startswith("VmRSS"))


def test_the_workers_memory_is_flat_from_frame_to_frame():
    """Full-size frames of changing views: the worker hands its freed temporaries back
    after each, so its resident memory is what it keeps (the wall patches), not what
    the allocator happened to hold on to (30-40 MB of swing without the trim), and a
    leak would show in the soak (station/bench/soak.py) above the noise."""
    from sim.camera.render import FrameParams

    params = FrameParams()
    rng = np.random.default_rng(4)
    views = [[HoleSpec(rng.uniform(200, 1000), rng.uniform(200, 800), rng.uniform(20, 120))
              for _ in range(rng.integers(1, 4))] for _ in range(14)]

    async def go():
        r = RendererProcess()
        await r.start()
        try:
            out = []
            for i, specs in enumerate(views):
                await r.render(params, specs, i, (i % 6, 0), i % 6)  # 6 views, 4 walls kept
                out.append(_rss_kb(r.pid))
            return out
        finally:
            r.stop()

    rss = asyncio.run(go())[6:]  # after the wall cache is full
    assert max(rss) - min(rss) < 4 * 1024, rss
