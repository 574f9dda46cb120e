"""``station.loopthread.LoopThread``: the one loop-in-a-thread helper (the API's station
thread, the twins' thread and the test kit's session thread are built on it)."""

from __future__ import annotations

import asyncio
import contextlib
import threading

import pytest

from station.loopthread import LoopThread


class _Resource:
    """An async context manager that notes on which thread it was entered and left."""

    def __init__(self, fail: bool = False):
        self.fail = fail
        self.entered_on = self.left_on = None

    async def __aenter__(self):
        self.entered_on = threading.current_thread().name
        await asyncio.sleep(0)
        if self.fail:
            raise OSError("cannot open")
        return self

    async def __aexit__(self, *exc):
        self.left_on = threading.current_thread().name


def test_runs_coroutines_and_functions_on_its_own_thread():
    with LoopThread("worker") as lt:
        assert lt.alive
        assert lt.run(asyncio.sleep(0, result=7), timeout=5) == 7
        assert lt.call(lambda: threading.current_thread().name, timeout=5) == "worker"
        fut = lt.submit(asyncio.sleep(0, result="x"))
        assert fut.result(5) == "x"
    assert not lt.alive and lt.loop is None


def test_a_timeout_cancels_the_coroutine():
    cancelled = threading.Event()

    async def forever():
        try:
            await asyncio.sleep(3600)
        except asyncio.CancelledError:
            cancelled.set()
            raise

    with LoopThread() as lt:
        with pytest.raises(TimeoutError):
            lt.run(forever(), timeout=0.05)
        assert cancelled.wait(5)


def test_context_is_entered_and_left_on_the_loop():
    res = _Resource()
    lt = LoopThread("holder").start()
    got = []
    value = lt.enter(lambda: res, setup=lambda r: got.append(threading.current_thread().name), timeout=5)
    assert value is res and res.entered_on == "holder" and got == ["holder"]
    assert res.left_on is None
    assert lt.stop(timeout=5)
    assert res.left_on == "holder"


def test_an_error_opening_reaches_the_caller_and_stop_still_ends_the_thread():
    lt = LoopThread().start()
    with pytest.raises(OSError, match="cannot open"):
        lt.enter(lambda: _Resource(fail=True), timeout=5)
    assert lt.stop(timeout=5) and not lt.alive


def test_a_context_that_will_not_close_is_cancelled_at_the_stop_timeout():
    @contextlib.asynccontextmanager
    async def stubborn():
        try:
            yield "v"
        finally:
            with contextlib.suppress(asyncio.CancelledError):
                await asyncio.sleep(3600)  # a close that hangs

    lt = LoopThread().start()
    assert lt.enter(stubborn, timeout=5) == "v"
    assert lt.stop(timeout=0.2)


def test_blocking_calls_from_the_loop_thread_are_refused():
    with LoopThread() as lt:
        err = lt.call(lambda: _try(lambda: lt.call(lambda: 1)), timeout=5)
        assert isinstance(err, RuntimeError) and "own thread" in str(err)


def test_submit_after_stop_is_refused():
    lt = LoopThread().start()
    lt.stop()
    coro = asyncio.sleep(0)
    with pytest.raises(RuntimeError, match="not running"):
        lt.submit(coro)


def _try(fn):
    try:
        fn()
    except Exception as exc:  # noqa: BLE001 - returned to the test
        return exc
    return None
