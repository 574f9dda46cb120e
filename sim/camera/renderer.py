"""The camera twin's pixels, rendered in a process of their own.

A real camera makes its pixels in its own silicon: the station's interpreter only
receives them. The twin's renderer costs tens of milliseconds of numpy per frame; in
the station's process it would take the interpreter's GIL from the drivers, the
engine and the API for that long, and the simulated station would be slower under
load than a real one. So the served station renders in a worker process (one,
started from a ``forkserver`` with the renderer preloaded, so a new worker starts in
milliseconds), and the twin itself (where the endoscope looks, which holes are in
view: the physics) stays in the station's process.

The worker keeps the wall patches (``sim.camera.twin``: a camera that stays put sees
the same wall) and sends back the 8-bit image. A worker that dies or does not answer
raises :class:`RendererLost`; the twin then renders in a thread. A worker whose
station process is gone (killed outright) ends itself within half a second.

As with any ``multiprocessing`` start method but fork, a script that starts a
simulated station must guard its entry with ``if __name__ == "__main__":`` (the
forkserver imports the main module); the ``station`` command does. Without the guard
the worker cannot start and the twin renders in a thread (with a warning).
"""

from __future__ import annotations

import asyncio
import concurrent.futures
import ctypes
import ctypes.util
import multiprocessing
import os
import threading
import time
from collections import OrderedDict
from concurrent.futures.process import BrokenProcessPool

import numpy as np

from sim.camera.render import FrameParams, HoleSpec, render_frame, wall_patch

#: wall patches kept (one per view position; 5 MB each at 1280 x 1024)
WALLS_KEPT = 4

#: the first frame waits for the worker's start; later ones for one render
START_TIMEOUT_S = 30.0
RENDER_TIMEOUT_S = 10.0


class RendererLost(RuntimeError):
    """The renderer process died, did not start or did not answer in time."""


def render_image(params: FrameParams, specs: list[HoleSpec], seed: int, wall_key: tuple[int, ...],
                 wall_seed: int, walls: OrderedDict, defects=()) -> np.ndarray:
    """Render one frame over the wall patch of ``wall_key`` (kept in ``walls``), with the
    surface defects in view (``sim.camera.defects.DefectSpec``)."""
    wall = walls.get(wall_key)
    if wall is None or wall.shape != (params.height_px, params.width_px):
        wall = wall_patch(params, wall_seed)
        walls[wall_key] = wall
        while len(walls) > WALLS_KEPT:
            walls.popitem(last=False)
    else:
        walls.move_to_end(wall_key)
    return render_frame(params, specs, seed, wall=wall, defects=defects).image


_WORKER_WALLS: OrderedDict = OrderedDict()


def _malloc_trim():
    """glibc's ``malloc_trim``, or None (another C library)."""
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
        fn = libc.malloc_trim
    except (OSError, AttributeError):
        return None
    fn.argtypes = [ctypes.c_size_t]
    fn.restype = ctypes.c_int
    return fn


_TRIM = _malloc_trim()


def _render_in_worker(params, specs, seed, wall_key, wall_seed, defects=()) -> np.ndarray:
    """One frame, then the frame's freed temporaries handed back to the system.

    A frame allocates tens of MB of temporaries; glibc keeps freed blocks in its heaps
    (its mmap threshold rises after the first large free), and which of them stay
    resident depends on the order of frees. The worker's resident memory then swings
    by 30-40 MB from frame to frame (157-200 MB over 30 frames of mixed views), which
    is neither needed nor a leak, and hides one in the soak (a CI run's soak failed on
    it: the renderer's least-squares slope over 12 inspections is noise of several
    hundred kB). ``malloc_trim(0)`` after each frame returns whole free pages (1.5 ms
    against ~150 ms of rendering): the same 30 frames then hold 122 MB, flat to the MB.
    """
    image = render_image(params, specs, seed, wall_key, wall_seed, _WORKER_WALLS, defects)
    if _TRIM is not None:
        _TRIM(0)
    return image


def _ready() -> bool:
    return True


def _watch_owner(owner_pid: int, period_s: float = 0.5) -> None:
    """In the worker: end it when the station process that owns it is gone.

    A station killed outright (SIGKILL, a crash) sends no goodbye, and a pool worker
    would wait on its queue forever (and keep the forkserver alive with it).
    """
    def watch() -> None:
        while True:
            time.sleep(period_s)
            try:
                os.kill(owner_pid, 0)
            except (ProcessLookupError, PermissionError):  # gone (or its pid reused by another user)
                os._exit(0)

    threading.Thread(target=watch, name="owner-watch", daemon=True).start()


_CONTEXT: multiprocessing.context.BaseContext | None = None


def _context() -> multiprocessing.context.BaseContext:
    """A forkserver that has imported the renderer (numpy, OpenCV) once for all workers;
    never a plain fork of the station's multi-threaded process."""
    global _CONTEXT
    if _CONTEXT is None:
        ctx = multiprocessing.get_context("forkserver")
        ctx.set_forkserver_preload(["sim.camera.render", "sim.camera.renderer"])
        _CONTEXT = ctx
    return _CONTEXT


class RendererProcess:
    """One worker process rendering the twin's frames."""

    def __init__(self) -> None:
        self._pool: concurrent.futures.ProcessPoolExecutor | None = None

    async def start(self) -> None:
        try:
            self._pool = concurrent.futures.ProcessPoolExecutor(max_workers=1, mp_context=_context(),
                                                                initializer=_watch_owner, initargs=(os.getpid(),))
            # the pool starts its worker inside its first submit, and starting it waits on
            # the forkserver (which itself starts and imports numpy and OpenCV the first
            # time): about a second on a loaded PC, so in a thread, off the event loop that
            # carries the station's heartbeats
            first = await asyncio.to_thread(self._pool.submit, _ready)
            await self._wait(asyncio.wrap_future(first), START_TIMEOUT_S)
        except (OSError, ValueError, BrokenProcessPool) as exc:
            self.stop()
            raise RendererLost(f"cannot start the renderer process: {exc}") from exc

    async def render(self, params: FrameParams, specs: list[HoleSpec], seed: int,
                     wall_key: tuple[int, ...], wall_seed: int, defects=()) -> np.ndarray:
        return await self._call(_render_in_worker, params, specs, seed, wall_key, wall_seed, tuple(defects),
                                timeout=RENDER_TIMEOUT_S)

    async def _call(self, fn, *args, timeout: float):
        if self._pool is None:
            raise RendererLost("the renderer process is stopped")
        loop = asyncio.get_running_loop()
        try:
            # the submit itself raises once the pool has seen its worker die (its manager
            # thread marks it broken), or after a shutdown: a loss as much as a failed future
            future = loop.run_in_executor(self._pool, fn, *args)
        except (BrokenProcessPool, RuntimeError) as exc:
            self.stop()
            raise RendererLost("the renderer process died") from exc
        return await self._wait(future, timeout)

    async def _wait(self, future: asyncio.Future, timeout: float):
        try:
            return await asyncio.wait_for(future, timeout)
        except (BrokenProcessPool, asyncio.TimeoutError) as exc:
            self.stop()
            what = "did not answer in time" if isinstance(exc, asyncio.TimeoutError) else "died"
            raise RendererLost(f"the renderer process {what}") from exc

    @property
    def pid(self) -> int | None:
        procs = getattr(self._pool, "_processes", None) or {}
        return next(iter(procs), None)

    def stop(self) -> None:
        pool, self._pool = self._pool, None
        if pool is not None:
            pool.shutdown(wait=False, cancel_futures=True)
