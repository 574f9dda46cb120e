"""Helpers shared by the routers: blocking calls off the event loop with a deadline,
size-limited uploads. (The runtime and the caller come as typed dependencies:
:mod:`api.deps`.)"""

from __future__ import annotations

import asyncio
import contextvars
import functools
from concurrent.futures import ThreadPoolExecutor
from typing import Any, Callable

from fastapi import HTTPException, UploadFile, status

#: a store call (SQLite with its 5 s busy timeout) or a short computation: give up after this
STORE_TIMEOUT_S = 15.0


#: the API's own worker threads: requests queue here, never in the default executor
#: that the inspection itself uses for its store writes (a burst of reads must not
#: hold up the running inspection's commits)
#: Two: more threads contend for the GIL with the station thread that carries the
#: drives' heartbeats (api/station_thread.py, station bench api).
API_THREADS = ThreadPoolExecutor(max_workers=2, thread_name_prefix="api")


async def in_api_thread(fn: Callable[..., Any], *args: Any, **kwargs: Any) -> Any:
    """``asyncio.to_thread`` on the API's own threads."""
    ctx = contextvars.copy_context()
    call = functools.partial(ctx.run, fn, *args, **kwargs)
    return await asyncio.get_running_loop().run_in_executor(API_THREADS, call)


async def blocking(fn: Callable[..., Any], *args: Any, timeout: float = STORE_TIMEOUT_S, **kwargs: Any) -> Any:
    """Run a blocking call in a worker thread; 504 when it takes longer than ``timeout``."""
    try:
        return await asyncio.wait_for(in_api_thread(fn, *args, **kwargs), timeout=timeout)
    except asyncio.TimeoutError:
        raise HTTPException(status.HTTP_504_GATEWAY_TIMEOUT, f"gave up after {timeout:g} s") from None


async def read_upload(upload: UploadFile, limit: int, what: str) -> str:
    """The upload's text (UTF-8), at most ``limit`` bytes: 413 above it, 422 when not text."""
    data = await upload.read(limit + 1)
    if len(data) > limit:
        raise HTTPException(status.HTTP_413_CONTENT_TOO_LARGE,
                            f"{what} is larger than {limit} bytes")
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise HTTPException(status.HTTP_422_UNPROCESSABLE_CONTENT, f"{what} is not UTF-8 text: {exc.reason}") from None
