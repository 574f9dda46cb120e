"""Catch the station's event loop stalling, and say where it was.

The drives' heartbeats ride the station's event loop (``drivers.modbus_axis``): each
drive stops its axis with a communication-watchdog fault when no heartbeat came for
its timeout (1 s). Any synchronous work of a second on the loop (a kernel compiled, a
chart's limits solved, a process started) therefore faults a healthy scan, and on a
loaded PC a stall that takes 0.3 s on a quiet one can take three times as long. The
fault itself says only "watchdog expired"; what held the loop is gone by then.

``StallWatch`` keeps a tick on the loop and a plain thread beside it. When the tick
is older than ``limit_s`` (half the shortest watchdog), the thread takes the loop
thread's stack at once, and when the loop turns again the stall is logged once, as a
warning with its length and that stack, and kept in ``stalls``. It reads only its own
clock and the interpreter's frames: nothing on the loop waits for it. A stall that a
long cyclic garbage collection fell in says so (``gc.callbacks``): a full collection in
a long-lived process holds every thread, and leaves the loop's stack in its selector.
"""

from __future__ import annotations

import asyncio
import collections
import contextlib
import gc
import logging
import sys
import threading
import time
import traceback
from dataclasses import dataclass

log = logging.getLogger(__name__)

#: frames of the loop thread's stack kept for a stall (innermost last)
STACK_FRAMES = 8
#: ... and of each other thread's, when the loop's was only waiting
OTHER_FRAMES = 4
#: the loop thread's innermost function when it waits for I/O or a timer (not working)
WAITING = frozenset({"select", "poll", "epoll", "_run_once"})
#: other threads idle in these are left out of a stall's report
WAITING_ELSEWHERE = frozenset({"wait", "select", "poll", "accept", "recv", "recv_into", "read", "readinto",
                               "_wait_for_tstate_lock", "get", "_worker", "sleep", "serve_forever"})


#: a cyclic garbage collection this long is kept, to be named in a stall it falls in
LONG_COLLECTION_S = 0.05


class _Collections:
    """The interpreter's cyclic garbage collections, timed through ``gc.callbacks``: a
    full collection holds the interpreter (every thread, the loop's among them) for as
    long as it takes to walk every tracked object, which in a long-lived process can be a
    second. The long ones are kept, as (start, end, generation, objects freed)."""

    def __init__(self, keep_s: float = LONG_COLLECTION_S) -> None:
        self.keep_s = keep_s
        self.long: collections.deque[tuple[float, float, int, int]] = collections.deque(maxlen=32)
        self._start: float | None = None

    def __call__(self, phase: str, info: dict) -> None:
        if phase == "start":
            self._start = time.monotonic()
        elif self._start is not None:
            end = time.monotonic()
            if end - self._start >= self.keep_s:
                self.long.append((self._start, end, int(info.get("generation", -1)),
                                  int(info.get("collected", 0))))
            self._start = None

    def within(self, t0: float, t1: float) -> str:
        """The long collections that overlapped [t0, t1], said in a line (empty if none)."""
        hit = [c for c in list(self.long) if c[1] > t0 and c[0] < t1]
        if not hit:
            return ""
        held = sum(min(e, t1) - max(s, t0) for s, e, _, _ in hit)
        kinds = ", ".join(f"generation {g} for {e - s:.2f} s ({n} objects freed)" for s, e, g, n in hit)
        return f"the interpreter's garbage collector held every thread for {held:.2f} s of it: {kinds}"


@dataclass(frozen=True)
class Stall:
    """One stall: how long the loop did not turn (s, at least; the watcher's own
    period rounds it), and where the loop thread was when it was seen."""

    seconds: float
    where: str


class StallWatch:
    """``async with StallWatch(limit_s) as w:`` watches the running loop while inside."""

    def __init__(self, limit_s: float = 0.5, name: str = "station") -> None:
        if not limit_s > 0:
            raise ValueError("limit_s must be positive")
        self.limit_s = float(limit_s)
        self.name = name
        #: the stalls seen so far (also logged as warnings)
        self.stalls: list[Stall] = []
        self._period_s = self.limit_s / 5.0
        self._seen = time.monotonic()
        self._tid: int | None = None
        self._ticker: asyncio.Task | None = None
        self._thread: threading.Thread | None = None
        self._stop = threading.Event()
        self._collections = _Collections()

    async def __aenter__(self) -> "StallWatch":
        self._tid = threading.get_ident()
        self._seen = time.monotonic()
        self._ticker = asyncio.create_task(self._tick(), name=f"{self.name}-stall-tick")
        self._stop.clear()
        gc.callbacks.append(self._collections)
        self._thread = threading.Thread(target=self._watch, name=f"{self.name}-stallwatch", daemon=True)
        self._thread.start()
        return self

    async def __aexit__(self, *exc) -> None:
        self._stop.set()
        with contextlib.suppress(ValueError):
            gc.callbacks.remove(self._collections)
        if self._ticker is not None:
            self._ticker.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await self._ticker
        if self._thread is not None:
            await asyncio.to_thread(self._thread.join, 5.0)

    async def _tick(self) -> None:
        while True:
            self._seen = time.monotonic()
            await asyncio.sleep(self._period_s)

    def _stack(self) -> str:
        frames = sys._current_frames()
        frame = frames.get(self._tid)
        if frame is None:
            return "(the loop's thread has ended)"
        lines = traceback.format_stack(frame)[-STACK_FRAMES:]
        where = "".join(lines).rstrip()
        if frame.f_code.co_name in WAITING:
            # the loop was waiting, not working: it could not take the interpreter back
            # from another thread (a compiled kernel that keeps the GIL, say), or the
            # process was not scheduled at all. The other threads say which
            names = {t.ident: t.name for t in threading.enumerate()}
            others = []
            for tid, f in frames.items():
                if tid in (self._tid, threading.get_ident()) or f.f_code.co_name in WAITING_ELSEWHERE:
                    continue
                stack = "".join(traceback.format_stack(f)[-OTHER_FRAMES:]).rstrip()
                others.append(f"thread {names.get(tid, tid)!r}:\n{stack}")
            where += ("\nthe loop's thread was waiting; the other threads that were not:\n" + "\n".join(others)
                      if others else "\nthe loop's thread was waiting, and so was every other thread (the process "
                                     "was not scheduled: a loaded machine)")
        return where

    def _watch(self) -> None:
        stalled_since: float | None = None
        where = ""
        while not self._stop.wait(self._period_s):
            seen = self._seen
            age = time.monotonic() - seen
            if stalled_since is None and age > self.limit_s:
                stalled_since, where = seen, self._stack()
            elif stalled_since is not None and seen != stalled_since:
                self._record(stalled_since, seen, where)
                stalled_since = None
        if stalled_since is not None:
            self._record(stalled_since, time.monotonic(), where)

    def _record(self, since: float, until: float, where: str) -> None:
        seconds = until - since
        collector = self._collections.within(since, until)
        if collector:
            where += "\n" + collector
        stall = Stall(seconds, where)
        self.stalls.append(stall)
        log.warning("the %s event loop did not turn for %.2f s (the drives' heartbeats ride it, and a drive's "
                    "watchdog faults the axis after its timeout); it was in:\n%s", self.name, seconds, where)


_frozen_lock = threading.Lock()
_frozen_sessions = 0


@contextlib.contextmanager
def heap_frozen():
    """While inside, the objects that existed on entry are left out of the interpreter's
    cyclic collections (``gc.freeze``); on the way out of the last such block they are
    handed back (``gc.unfreeze``).

    A full collection walks every tracked object and holds every thread while it does:
    in a process that has loaded the vision's kernels, the store, the web app and (in a
    test run) a thousand tests' leftovers, that is 0.4-0.75 s on this two-core PC, and on
    a loaded one it outlasts a drive's watchdog. What a session makes while it is open is
    what its collections need to walk. The garbage of the moment is collected first, so
    that none is kept for the block's life: enter before the drives connect, since that
    collection is the long one (it walks only what is not frozen already). Blocks may
    nest or overlap (several sessions in one process: a web app's, a test's): the heap
    is handed back when the last one ends, and each one's entry freezes what has come
    since."""
    global _frozen_sessions
    with _frozen_lock:
        gc.collect()
        gc.freeze()
        _frozen_sessions += 1
    try:
        yield
    finally:
        with _frozen_lock:
            _frozen_sessions -= 1
            if _frozen_sessions == 0:
                gc.unfreeze()
