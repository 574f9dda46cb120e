"""One asyncio event loop in a daemon thread, driven from other threads.

Three places need an event loop of their own beside their caller: the API keeps the
station's loop apart from uvicorn's (``api.station_thread``), synchronous callers
(the CLI, benches, sync tests) run the twins' servers in one (``sim.twins``), and the
fault matrix keeps one inspection session alive across many test cells
(``testkit.session``). Each had its own hand-written thread, and each got the hard
parts a little differently: reporting an error raised while opening, entering and
leaving an async context manager *on the loop that runs it* (drivers and servers bind
to the loop they were opened on), and a stop that cannot hang its caller. This module
is that machinery once; it knows nothing of the station.

Everything crosses between threads through the loop's thread-safe entry points
(``asyncio.run_coroutine_threadsafe``, ``call_soon_threadsafe``) and
``concurrent.futures.Future``; a caller on another event loop awaits those futures
with ``asyncio.wrap_future``. Blocking calls made from the loop's own thread would
wait for themselves, so they are refused.
"""

from __future__ import annotations

import asyncio
import concurrent.futures
import contextlib
import logging
import threading
from typing import Any, AsyncContextManager, Callable, Coroutine, TypeVar

log = logging.getLogger(__name__)

T = TypeVar("T")

#: how long a loop may take to start running: it only creates a loop and a thread, so
#: this is generous even on a loaded two-core PC
START_TIMEOUT_S = 10.0
#: how long a clean stop may take (leaving the context: closing drives, servers, a
#: store) before the caller is given back control and the thread is left to end alone
STOP_TIMEOUT_S = 30.0


class LoopThread:
    """An asyncio loop running in a daemon thread, and what other threads do with it.

    * :meth:`start` runs the loop; :meth:`stop` ends it and joins the thread;
    * :meth:`enter` (blocking) or :meth:`entering` (a future) enter an async context
      manager on the loop and hold it until :meth:`stop`, which leaves it there;
    * :meth:`submit` schedules a coroutine (a ``concurrent.futures.Future``);
      :meth:`run` and :meth:`call` run a coroutine or a plain function and wait for
      the result; :meth:`call_soon` fires and forgets.
    """

    def __init__(self, name: str = "loop") -> None:
        self.name = name
        #: the running loop (None before :meth:`start` and after :meth:`stop`)
        self.loop: asyncio.AbstractEventLoop | None = None
        self._thread: threading.Thread | None = None
        #: the task holding the entered context, and the event that tells it to leave
        self._holder: concurrent.futures.Future | None = None
        self._leave: asyncio.Event | None = None

    # ------------------------------------------------------------------ life cycle
    @property
    def alive(self) -> bool:
        return self._thread is not None and self._thread.is_alive()

    def start(self, timeout: float = START_TIMEOUT_S) -> "LoopThread":
        """Start the thread and wait (at most ``timeout`` s) until its loop runs."""
        if self._thread is not None:
            raise RuntimeError(f"the {self.name} thread runs already")
        ready = threading.Event()
        self._thread = threading.Thread(target=self._run, args=(ready,), name=self.name, daemon=True)
        self._thread.start()
        if not ready.wait(timeout):
            raise TimeoutError(f"the {self.name} loop did not start within {timeout:.0f} s")
        return self

    def _run(self, ready: threading.Event) -> None:
        loop = asyncio.new_event_loop()
        asyncio.set_event_loop(loop)
        self.loop = loop
        loop.call_soon(ready.set)
        try:
            loop.run_forever()
        finally:
            try:
                # what is still running when the loop stops (a context that would not
                # close in time, a forgotten task) is cancelled and given its cleanup
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

    def stop(self, timeout: float = STOP_TIMEOUT_S) -> bool:
        """Leave the entered context on the loop (at most ``timeout`` s, then it is
        cancelled), stop the loop and join the thread (at most ``timeout`` s).
        Returns whether the thread ended; a thread that did not is logged and left
        to end by itself (it is a daemon: it never holds the process)."""
        loop, thread, holder = self.loop, self._thread, self._holder
        if thread is None:
            return True
        if holder is not None and not holder.done() and loop is not None and not loop.is_closed():
            with contextlib.suppress(RuntimeError):  # the loop closed meanwhile
                loop.call_soon_threadsafe(self._signal_leave)
            try:
                holder.result(timeout)
            except concurrent.futures.TimeoutError:
                log.error("%s: the context did not close within %.0f s; cancelled", self.name, timeout)
                holder.cancel()
            except BaseException as exc:  # noqa: BLE001 - an error while leaving is reported, not raised
                if not isinstance(exc, concurrent.futures.CancelledError):
                    log.warning("%s: leaving the context failed: %s: %s", self.name, type(exc).__name__, exc)
        if loop is not None:
            with contextlib.suppress(RuntimeError):  # closed already
                loop.call_soon_threadsafe(loop.stop)
        thread.join(timeout)
        if thread.is_alive():
            log.error("%s: the thread did not end within %.0f s", self.name, timeout)
            return False
        self._thread = None
        self.loop = None
        self._holder = None
        self._leave = None
        return True

    def _signal_leave(self) -> None:
        if self._leave is not None:
            self._leave.set()

    def __enter__(self) -> "LoopThread":
        return self.start()

    def __exit__(self, *exc: Any) -> None:
        self.stop()

    # ------------------------------------------------------------------ a context held on the loop
    def entering(self, context: Callable[[], AsyncContextManager[T]],
                 setup: Callable[[T], Any] | None = None) -> concurrent.futures.Future:
        """Enter ``context()`` on the loop, run ``setup(value)`` there (a plain or a
        coroutine function), and hold the context until :meth:`stop`. Returns a future
        of the context's value, or of the error that opening (or ``setup``) raised;
        the context is left before that error reaches the future."""
        if self._holder is not None:
            raise RuntimeError(f"the {self.name} thread holds a context already")
        entered: concurrent.futures.Future = concurrent.futures.Future()
        # created here, set on the loop: an Event binds to a loop only when awaited
        self._leave = asyncio.Event()
        self._holder = self.submit(self._hold(context, setup, entered, self._leave))
        self._holder.add_done_callback(lambda f: _settle_entered(entered, f))
        return entered

    def enter(self, context: Callable[[], AsyncContextManager[T]], setup: Callable[[T], Any] | None = None,
              timeout: float | None = None) -> T:
        """:meth:`entering`, waiting for the value (at most ``timeout`` s; None: as
        long as opening takes). On a timeout the opening is cancelled and
        ``TimeoutError`` raised; either way :meth:`stop` is the caller's to call."""
        self._refuse_own_thread("enter")
        entered = self.entering(context, setup)
        try:
            return entered.result(timeout)
        except concurrent.futures.TimeoutError:
            if self._holder is not None:
                self._holder.cancel()
            raise TimeoutError(f"{self.name}: not open within {timeout:.0f} s") from None

    @staticmethod
    async def _hold(context, setup, entered: concurrent.futures.Future, leave: asyncio.Event) -> None:
        async with context() as value:
            if setup is not None:
                out = setup(value)
                if asyncio.iscoroutine(out):
                    await out
            if not entered.done():
                entered.set_result(value)
            await leave.wait()

    # ------------------------------------------------------------------ calls from other threads
    def submit(self, coro: Coroutine[Any, Any, Any]) -> concurrent.futures.Future:
        """Schedule ``coro`` on the loop; its future is thread-safe (``result``,
        ``cancel``: cancelling it cancels the coroutine)."""
        loop = self.loop
        if loop is None or loop.is_closed():
            coro.close()
            raise RuntimeError(f"the {self.name} thread is not running")
        return asyncio.run_coroutine_threadsafe(coro, loop)

    def run(self, coro: Coroutine[Any, Any, Any], timeout: float | None = None) -> Any:
        """Run ``coro`` on the loop and wait for its result (at most ``timeout`` s:
        then it is cancelled and ``TimeoutError`` raised)."""
        self._refuse_own_thread("run", coro)
        fut = self.submit(coro)
        try:
            return fut.result(timeout)
        except concurrent.futures.TimeoutError:
            fut.cancel()
            raise

    def call(self, fn: Callable[..., Any], *args: Any, timeout: float | None = None, **kwargs: Any) -> Any:
        """Call a plain function on the loop's thread and wait for its result (state
        the loop's objects own is touched there, never from another thread)."""

        async def once() -> Any:
            return fn(*args, **kwargs)

        return self.run(once(), timeout)

    def call_soon(self, fn: Callable[..., Any], *args: Any) -> None:
        """Fire and forget ``fn(*args)`` on the loop (nothing happens once it is closed)."""
        loop = self.loop
        if loop is not None:
            with contextlib.suppress(RuntimeError):
                loop.call_soon_threadsafe(fn, *args)

    def _refuse_own_thread(self, what: str, coro: Coroutine | None = None) -> None:
        if self._thread is not None and threading.current_thread() is self._thread:
            if coro is not None:
                coro.close()
            raise RuntimeError(f"{self.name}: {what} from the loop's own thread would wait for itself")


def _settle_entered(entered: concurrent.futures.Future, holder: concurrent.futures.Future) -> None:
    """The holder ended: an ``entered`` nobody resolved yet learns why (the opening
    failed, was cancelled, or the context ended by itself)."""
    if entered.done():
        return
    if holder.cancelled():
        entered.set_exception(RuntimeError("the context was cancelled while opening"))
    elif holder.exception() is not None:
        entered.set_exception(holder.exception())
    else:
        entered.set_exception(RuntimeError("the context ended while opening"))


__all__ = ["LoopThread", "START_TIMEOUT_S", "STOP_TIMEOUT_S"]
