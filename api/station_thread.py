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
with a timeout.
"""

from __future__ import annotations

import asyncio
import concurrent.futures
import contextlib
import logging
import threading
from typing import Any, AsyncContextManager, Callable, Coroutine, TypeVar

log = logging.getLogger("api")

T = TypeVar("T")

#: how long a clean stop may take (closing the drives and the twins) before giving up on it
STOP_TIMEOUT_S = 30.0


class StationThread:
    """A thread running one asyncio loop that holds the station session."""

    def __init__(self, name: str = "station") -> None:
        self.name = name
        self.loop: asyncio.AbstractEventLoop | None = None
        self._thread: threading.Thread | None = None
        self._ready = threading.Event()
        self._holder: concurrent.futures.Future | None = None
        self._leave: asyncio.Event | None = None  # set on the station loop: leave the session

    # ------------------------------------------------------------------ life cycle
    async def start(self, context: Callable[[], AsyncContextManager[T]],
                    setup: Callable[[T], Any] | None = None) -> T:
        """Start the thread, enter ``context()`` on its loop, run ``setup(value)`` there
        (a plain function or a coroutine function) and return the context's value."""
        if self._thread is not None:
            raise RuntimeError("the station thread runs already")
        self._thread = threading.Thread(target=self._run, name=self.name, daemon=True)
        self._thread.start()
        await asyncio.to_thread(self._ready.wait, 10.0)
        if self.loop is None:
            raise RuntimeError("the station loop did not start")
        entered: concurrent.futures.Future = concurrent.futures.Future()
        self._holder = asyncio.run_coroutine_threadsafe(self._hold(context, setup, entered), self.loop)
        # a failed open ends the holder with the error: it resolves ``entered`` too
        self._holder.add_done_callback(lambda f: _settle_cf(entered, f))
        try:
            return await asyncio.wrap_future(entered)
        except BaseException:
            await self.stop()
            raise

    async def _hold(self, context, setup, entered: concurrent.futures.Future) -> None:
        self._leave = asyncio.Event()
        async with context() as value:
            if setup is not None:
                out = setup(value)
                if asyncio.iscoroutine(out):
                    await out
            if not entered.done():
                entered.set_result(value)
            await self._leave.wait()

    def _run(self) -> None:
        loop = asyncio.new_event_loop()
        asyncio.set_event_loop(loop)
        self.loop = loop
        loop.call_soon(self._ready.set)
        try:
            loop.run_forever()
        finally:
            try:
                pending = [t for t in asyncio.all_tasks(loop) if not t.done()]
                for t in pending:
                    t.cancel()
                if pending:
                    loop.run_until_complete(asyncio.gather(*pending, return_exceptions=True))
                loop.run_until_complete(loop.shutdown_asyncgens())
                loop.run_until_complete(loop.shutdown_default_executor())
            finally:
                asyncio.set_event_loop(None)
                loop.close()

    async def stop(self, timeout: float = STOP_TIMEOUT_S) -> None:
        """Leave the session on the station loop, stop the loop, join the thread."""
        loop, thread = self.loop, self._thread
        if loop is None or thread is None:
            return
        if self._holder is not None and not self._holder.done() and not loop.is_closed():
            loop.call_soon_threadsafe(self._signal_leave)
            with contextlib.suppress(BaseException):
                await asyncio.wait_for(asyncio.shield(asyncio.wrap_future(self._holder)), timeout=timeout)
            if not self._holder.done():
                log.error("the station session did not close within %.0f s", timeout)
                self._holder.cancel()
        with contextlib.suppress(RuntimeError):  # closed already
            loop.call_soon_threadsafe(loop.stop)
        await asyncio.to_thread(thread.join, timeout)
        if thread.is_alive():
            log.error("the station thread did not end within %.0f s", timeout)
        else:
            self._thread = None
            self.loop = None

    def _signal_leave(self) -> None:
        if self._leave is not None:
            self._leave.set()

    @property
    def alive(self) -> bool:
        return self._thread is not None and self._thread.is_alive()

    # ------------------------------------------------------------------ calls
    def submit(self, coro: Coroutine[Any, Any, T]) -> concurrent.futures.Future:
        """Run ``coro`` on the station loop; its future is thread-safe (done(), cancel())."""
        if self.loop is None:
            coro.close()
            raise RuntimeError("the station thread is not running")
        return asyncio.run_coroutine_threadsafe(coro, self.loop)

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
        if self.loop is not None:
            self.loop.call_soon_threadsafe(fn, *args)


def _settle_cf(target: concurrent.futures.Future, source: concurrent.futures.Future) -> None:
    if target.done():
        return
    if source.cancelled():
        target.set_exception(RuntimeError("the station session was cancelled while opening"))
    elif source.exception() is not None:
        target.set_exception(source.exception())
    else:
        target.set_exception(RuntimeError("the station session ended while opening"))


def to_loop(loop: asyncio.AbstractEventLoop) -> Callable[..., None]:
    """``fn(*args)`` on ``loop`` from any thread (dropped once the loop is closed)."""

    def hop(fn: Callable[..., Any], *args: Any) -> None:
        with contextlib.suppress(RuntimeError):
            loop.call_soon_threadsafe(fn, *args)

    return hop


__all__ = ["StationThread", "to_loop"]
