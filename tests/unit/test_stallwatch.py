"""The station's loop-stall watch: a stall is caught, timed, and placed."""

from __future__ import annotations

import asyncio
import logging
import time

from station.stallwatch import StallWatch


def _hold_the_loop(seconds: float) -> None:
    time.sleep(seconds)  # synchronous work on the loop: what faults a drive's watchdog


def _watch_a_held_loop(limit_s: float, lead_s: float, hold_s: float, tail_s: float, before_hold=None) -> StallWatch:
    """A loop under a ``StallWatch(limit_s)``: it awaits ``lead_s``, calls
    ``before_hold(watch)`` if given, holds the loop for ``hold_s``, awaits ``tail_s``."""

    async def go():
        async with StallWatch(limit_s=limit_s, name="test") as w:
            await asyncio.sleep(lead_s)
            if before_hold is not None:
                before_hold(w)
            _hold_the_loop(hold_s)
            await asyncio.sleep(tail_s)
        return w

    return asyncio.run(go())


def test_a_stall_is_logged_with_its_length_and_the_code_that_held_the_loop(caplog):
    with caplog.at_level(logging.WARNING, logger="station.stallwatch"):
        w = _watch_a_held_loop(0.2, 0.1, 0.8, 0.2)
    held = [s for s in w.stalls if "_hold_the_loop" in s.where]
    assert len(held) == 1, w.stalls
    # the gap between the loop's ticks: the 0.8 s held, plus at most a tick's period
    # and whatever a loaded PC adds
    assert held[0].seconds >= 0.75, held
    assert any("_hold_the_loop" in r.getMessage() and "did not turn" in r.getMessage() for r in caplog.records)


def test_a_loop_that_only_awaits_is_not_reported_and_the_watch_ends_its_thread():
    async def go():
        gaps, t = [], time.monotonic()
        async with StallWatch(limit_s=0.5, name="test") as w:
            for _ in range(10):
                await asyncio.sleep(0.03)
                now = time.monotonic()
                gaps.append(now - t)
                t = now
        return w, max(gaps)

    w, longest = asyncio.run(go())
    # the loop's own longest turn bounds what the watch may report (a loaded PC can
    # stall even an idle loop, but never for longer than the loop itself saw)
    assert not w.stalls or longest > 0.5, (w.stalls, longest)
    assert all(s.seconds <= longest + 0.2 for s in w.stalls), (w.stalls, longest)
    assert not w._thread.is_alive()


def test_a_loop_waiting_for_the_interpreter_names_the_threads_that_were_busy():
    """A stall with the loop's thread in its selector is no work of the loop's: another
    thread kept the interpreter (a compiled kernel holding the GIL) or the process was not
    scheduled. The stack then lists the other threads that were not idle (a CI run's
    watchdog fault logged only the loop's ``select``)."""
    import threading

    stop = threading.Event()

    def _busy_elsewhere() -> None:
        while not stop.is_set():
            sum(range(1000))

    async def go():
        async with StallWatch(limit_s=0.5, name="test") as w:
            worker = threading.Thread(target=_busy_elsewhere, name="busy-worker", daemon=True)
            worker.start()
            try:
                await asyncio.sleep(0.3)
                # read from another thread, as the watch does, while the loop's thread sits
                # in its selector awaiting that thread
                def later() -> str:
                    time.sleep(0.2)  # the loop's thread back in its selector meanwhile
                    return w._stack()

                return await asyncio.to_thread(later)
            finally:
                stop.set()
                worker.join(5.0)

    where = asyncio.run(go())
    assert "the loop's thread was waiting" in where, where
    assert "busy-worker" in where and "_busy_elsewhere" in where, where


def test_a_stall_that_a_garbage_collection_fell_in_names_the_collector():
    """A full cyclic collection holds every thread of the process: in a long-lived one
    (the station's, or a test run's after a thousand tests) it can outlast a drive's
    watchdog, and the loop's stack then shows only its selector. The stall says so."""
    import gc

    def collect(w: StallWatch) -> None:
        w._collections.keep_s = 0.0  # keep every collection, however short, for the test
        gc.collect()  # a full collection, inside the stall the hold that follows makes

    w = _watch_a_held_loop(0.1, 0.05, 0.3, 0.1, before_hold=collect)
    assert w._collections not in gc.callbacks  # the watch takes its hook away
    named = [s for s in w.stalls if "garbage collector held every thread" in s.where]
    assert len(named) == 1, w.stalls
    assert "generation 2" in named[0].where


def test_a_stall_with_no_collection_in_it_does_not_blame_the_collector():
    import gc

    gc.disable()  # no collection may fall in the stall (its absence is what is tested)
    try:
        w = _watch_a_held_loop(0.1, 0.05, 0.3, 0.1)
    finally:
        gc.enable()
    assert [s for s in w.stalls if "_hold_the_loop" in s.where], w.stalls
    assert not any("garbage collector" in s.where for s in w.stalls)


_FREEZE_PROBE = r"""
import gc, json, weakref
from station.stallwatch import heap_frozen

class Node:
    pass

out = {"before": gc.get_freeze_count()}
garbage = Node(); garbage.me = garbage; gone = weakref.ref(garbage); del garbage  # a cycle already unreachable
kept = Node(); kept.me = kept; alive = weakref.ref(kept)  # a cycle alive on entry
first = heap_frozen()
first.__enter__()
out["garbage_of_the_moment_collected"] = gone() is None
out["frozen_inside"] = gc.get_freeze_count()
with heap_frozen():  # a second session, overlapping the first
    inner = Node(); inner.me = inner
out["frozen_after_the_second_left"] = gc.get_freeze_count()
del kept
gc.collect()
out["frozen_cycle_walked"] = alive() is None
first.__exit__(None, None, None)
out["frozen_after_the_last_left"] = gc.get_freeze_count()
gc.collect()
out["handed_back_and_collected"] = alive() is None
print(json.dumps(out))
"""


def test_a_sessions_heap_is_left_out_of_collections_while_open_and_handed_back_after_the_last():
    """``heap_frozen``: the garbage of the moment is collected on entry (none is kept for
    the session's life); the objects alive then are not walked by the collections of its
    life (a full one over a test run's or a station's heap held the loop for 0.4-0.75 s);
    overlapping sessions hand the heap back only when the last ends, and a cycle made
    unreachable meanwhile is then collected as usual. In an interpreter of its own: a
    test run holds sessions open for its whole length (the API tests' server)."""
    import json
    import subprocess
    import sys

    done = subprocess.run([sys.executable, "-c", _FREEZE_PROBE], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr[-2000:]
    out = json.loads(done.stdout.strip().splitlines()[-1])
    assert out["before"] == 0
    assert out["garbage_of_the_moment_collected"], "garbage of the moment was frozen with the heap"
    assert out["frozen_inside"] > 0
    # the second's end must not hand the heap back while the first is open
    assert out["frozen_after_the_second_left"] >= out["frozen_inside"]
    assert not out["frozen_cycle_walked"], "a frozen object was walked by a collection"
    assert out["frozen_after_the_last_left"] == 0
    assert out["handed_back_and_collected"], "the heap was not handed back: its garbage is kept for good"
