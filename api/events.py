"""Fan-out of live events to every Server-Sent-Events client.

The engine calls its listeners synchronously from the event loop; the hub copies each
event into every subscriber's bounded queue. A slow client loses its oldest events
rather than growing memory or slowing the sequencer: a panel needs the present state,
not a complete history (that is in the store's event log).
"""

from __future__ import annotations

import asyncio
import itertools
import json
import time
from dataclasses import dataclass, field
from typing import Any

#: events a subscriber may fall behind by before its oldest are dropped
QUEUE_SIZE = 256


@dataclass
class LiveEvent:
    kind: str  # state, progress, note, retry, fault, job
    data: dict[str, Any]
    id: int = 0
    time: float = field(default_factory=time.time)

    def sse(self) -> bytes:
        """The event in SSE framing: ``id``, ``event``, one ``data`` line of JSON, blank line."""
        payload = json.dumps({"time": self.time, **self.data}, allow_nan=False, default=str)
        return f"id: {self.id}\nevent: {self.kind}\ndata: {payload}\n\n".encode()


class EventHub:
    def __init__(self) -> None:
        self._subscribers: set[asyncio.Queue] = set()
        self._ids = itertools.count(1)
        self.closed = False

    def publish(self, kind: str, **data: Any) -> None:
        ev = LiveEvent(kind, data, next(self._ids))
        for q in list(self._subscribers):
            if q.full():
                try:
                    q.get_nowait()  # drop the oldest: see module docstring
                except asyncio.QueueEmpty:
                    pass
            q.put_nowait(ev)

    def subscribe(self) -> asyncio.Queue:
        q: asyncio.Queue = asyncio.Queue(QUEUE_SIZE)
        self._subscribers.add(q)
        return q

    def unsubscribe(self, q: asyncio.Queue) -> None:
        self._subscribers.discard(q)

    def close(self) -> None:
        """Tell every stream to end (the server is shutting down)."""
        self.closed = True
        for q in list(self._subscribers):
            if q.full():
                q.get_nowait()
            q.put_nowait(None)

    @property
    def subscriber_count(self) -> int:
        return len(self._subscribers)
