"""The station's own event loop, in a thread of the API process.

The drives' heartbeats (a write every 100 ms, a 500 ms watchdog in the drive), the
engine, the encoder and the camera run on this loop; the API's requests run on
uvicorn's. A burst of requests therefore delays only other requests: the station's
loop never waits behind a request handler (it still shares the interpreter's GIL,
which Python hands between threads every few milliseconds).

The two loops talk only through thread-safe calls:

* API -> station: :meth:`StationThread.call` (``asyncio.run_coroutine_threadsafe``
  on the station loop, awaited on the API loop through ``asyncio.wrap_future``;
  cancelling the awaiting request cancels the station's coroutine) and
  :meth:`StationThread.submit` (the ``concurrent.futures.Future`` of a background job).
* station -> API: the runtime's callbacks hop with ``api_loop.call_soon_threadsafe``
  (engine events for the SSE hub and the metrics, camera frames for the MJPEG stream).

One object owns the thread: :meth:`start` runs the loop and enters the station
session on it (``open_session`` must be entered and left on the loop that runs the
drivers), :meth:`stop` leaves the session there, stops the loop and joins the thread
with a timeout. The thread itself is :class:`station.loopthread.LoopThread` (the one
loop-in-a-thread helper, shared with the twins and the test kit); this class is its
face for callers that live on another event loop: every wait is awaited, never
blocking the API loop.
"""

from __future__ import annotations

import asyncio
import concurrent.futures
import contextlib
from typing import Any, AsyncContextManager, Callable, Coroutine, TypeVar

from station.loopthread import START_TIMEOUT_S, STOP_TIMEOUT_S, LoopThread

T = TypeVar("T")


class StationThread:
    """A thread running one asyncio loop that holds the station session."""

    def __init__(self, name: str = "station") -> None:
        self.name = name
        self._runner = LoopThread(name)

    @property
    def loop(self) -> asyncio.AbstractEventLoop | None:
        """The station loop (None while the thread does not run)."""
        return self._runner.loop

    # ------------------------------------------------------------------ life cycle
    async def start(self, context: Callable[[], AsyncContextManager[T]],
                    setup: Callable[[T], Any] | None = None) -> T:
        """Start the thread, enter ``context()`` on its loop, run ``setup(value)`` there
        (a plain function or a coroutine function) and return the context's value."""
        if self._runner.alive:
            raise RuntimeError("the station thread runs already")
        await asyncio.to_thread(self._runner.start, START_TIMEOUT_S)
        try:
            # no time limit on opening: migrating a large store may take its time
            return await asyncio.wrap_future(self._runner.entering(context, setup))
        except BaseException:
            await self.stop()
            raise

    async def stop(self, timeout: float = STOP_TIMEOUT_S) -> None:
        """Leave the session on the station loop, stop the loop, join the thread (each
        at most ``timeout`` s; what did not end in time is logged)."""
        await asyncio.to_thread(self._runner.stop, timeout)

    @property
    def alive(self) -> bool:
        return self._runner.alive

    # ------------------------------------------------------------------ calls
    def submit(self, coro: Coroutine[Any, Any, T]) -> concurrent.futures.Future:
        """Run ``coro`` on the station loop; its future is thread-safe (done(), cancel())."""
        return self._runner.submit(coro)

    async def call(self, coro: Coroutine[Any, Any, T], timeout: float | None = None) -> T:
        """Await ``coro`` run on the station loop, from the API loop; ``timeout``
        (seconds) is kept on the API side, so a request answers even if the station
        loop does not. Cancelling the caller (or the timeout) cancels ``coro``."""
        fut = asyncio.wrap_future(self.submit(coro))
        if timeout is None:
            return await fut
        return await asyncio.wait_for(fut, timeout)

    async def run(self, fn: Callable[..., T], *args: Any, **kwargs: Any) -> T:
        """Call a plain function on the station loop (what touches the engine's
        asyncio objects, or state the station reads, must happen there)."""

        async def once() -> T:
            return fn(*args, **kwargs)

        return await self.call(once())

    def call_soon(self, fn: Callable[..., Any], *args: Any) -> None:
        """Fire and forget ``fn(*args)`` on the station loop."""
        self._runner.call_soon(fn, *args)


def to_loop(loop: asyncio.AbstractEventLoop) -> Callable[..., None]:
    """``fn(*args)`` on ``loop`` from any thread (dropped once the loop is closed)."""

    def hop(fn: Callable[..., Any], *args: Any) -> None:
        with contextlib.suppress(RuntimeError):
            loop.call_soon_threadsafe(fn, *args)

    return hop


__all__ = ["StationThread", "to_loop"]
