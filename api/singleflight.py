"""Coalescing of identical concurrent reads ("single flight").

Fifty MES clients polling the same running inspection ask the database the same
question at the same moment; one read answers them all. A caller joins a read that
is still in flight, so what it gets is at most one read's duration older than its
request: the same freshness a slightly earlier request would have had. Nothing is
kept once the read ends (this is not a cache).
"""

from __future__ import annotations

import asyncio
from typing import Any, Awaitable, Callable, Hashable


class SingleFlight:
    def __init__(self) -> None:
        self._inflight: dict[Hashable, asyncio.Future] = {}

    async def run(self, key: Hashable, call: Callable[[], Awaitable[Any]]) -> Any:
        fut = self._inflight.get(key)
        if fut is None:
            fut = asyncio.ensure_future(call())
            self._inflight[key] = fut

            def forget(f: asyncio.Future, key=key) -> None:
                if self._inflight.get(key) is f:
                    del self._inflight[key]
                if not f.cancelled():
                    f.exception()  # retrieved: no "never retrieved" warning when nobody waits any more

            fut.add_done_callback(forget)
        # shield: one impatient caller (a client that hung up) must not cancel the others' read
        return await asyncio.shield(fut)
