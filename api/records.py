"""Inspection records as the API serves them: read once per change, not per request.

Fifty MES clients polling a running inspection would each cost a database read in a
worker thread (a thread hop and the GIL handed back and forth, beside the station).
The record only changes when the station commits to it, and the store counts those
commits (:attr:`station.store.Store.record_generation`), so a record read at
generation *g* is exactly current while the store is still at *g*: no time-to-live,
no stale answers. Reads that miss are shared by concurrent callers (single flight).

Several stations on one database: only this station's commits move the generation, so
a record another station is still writing is never cached (read afresh each time),
while a finished record, which never changes, is served from the cache whoever wrote it.

Race: the generation is noted *before* the read. A commit landing during the read
moves the store past the noted value, so that possibly older record is never served
after the commit: the next request reads again.
"""

from __future__ import annotations

from collections import OrderedDict
from typing import Any, Awaitable, Callable

from api.singleflight import SingleFlight

#: records kept (the running inspection and the recently finished ones being polled)
KEPT = 256


class RecordCache:
    def __init__(self, store, read: Callable[[Callable[..., Any], str], Awaitable[Any]]) -> None:
        """``read(fn, inspection_id)`` runs the blocking ``fn(inspection_id)`` off the loop."""
        self._store = store
        self._read = read
        self._records: OrderedDict[str, tuple[int, Any]] = OrderedDict()
        self._flights = SingleFlight()
        self.hits = 0
        self.misses = 0

    async def get(self, inspection_id: str):
        now = self._store.record_generation
        kept = self._records.get(inspection_id)
        if kept is not None and (kept[0] == now or self._final_elsewhere(kept[1])):
            self._records.move_to_end(inspection_id)
            self.hits += 1
            return kept[1]
        self.misses += 1
        return await self._flights.run(("record", inspection_id, now), lambda: self._fetch(inspection_id))

    def _final_elsewhere(self, record) -> bool:
        """A finished record never changes (the store's "final means final"), whoever
        wrote it; it stays served after this station's own commits move on."""
        return getattr(record, "state", "running") != "running"

    def _cacheable(self, record) -> bool:
        """Only this station's commits move the generation: a record another station
        (sharing the database) is still writing is read afresh every time."""
        mine = getattr(self._store, "station_id", None)
        return getattr(record, "state", "running") != "running" or getattr(record, "station_id", mine) == mine

    async def _fetch(self, inspection_id: str):
        generation = self._store.record_generation  # before the read (see the module's note)
        record = await self._read(self._store.get, inspection_id)
        if not self._cacheable(record):
            return record
        self._records[inspection_id] = (generation, record)
        self._records.move_to_end(inspection_id)
        while len(self._records) > KEPT:
            self._records.popitem(last=False)
        return record
