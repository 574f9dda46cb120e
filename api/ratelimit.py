"""A per-token limit on writes: a token bucket for each API token.

Every request that changes something (POST, PUT, PATCH, DELETE) takes one unit from
its token's bucket; a bucket holds at most ``burst`` units and refills at
``rate_per_s``. An empty bucket means 429 with ``Retry-After`` (whole seconds until a
unit is back). Reads are not limited: polling is what an MES and the panel do all day,
and reads are served from caches (api/records.py). A panel session counts against the
token it was opened with, so a session cannot be used to get around its token's limit.

It is applied in :func:`api.auth.authenticate`, after the caller is known: an
unauthenticated request is refused (401) without touching a bucket, so nobody can
empty another token's bucket, and the number of buckets is bounded by the number of
valid tokens.

Cost per request: a dict lookup and a little arithmetic under a lock (routes run on
the event loop, tests and benches may call from threads). Memory: a bucket that has
been idle long enough to be full again is the same as no bucket, so buckets are kept
in least-recently-used order and full ones are dropped from the old end as requests
come (O(1) amortised); ``max_keys`` bounds the table whatever happens.
"""

from __future__ import annotations

import math
import threading
import time
from collections import OrderedDict
from collections.abc import Callable, Hashable
from dataclasses import dataclass

#: most buckets kept (a station has a handful of tokens; this only bounds a mistake)
MAX_KEYS = 10_000


@dataclass
class _Bucket:
    level: float  # units available now (at ``at``)
    at: float  # clock time of ``level``


class WriteLimiter:
    """Token buckets by key (an API token's id); ``rate_per_s <= 0`` turns the limit off.

    ``clock`` is a monotonic clock in seconds (injected by tests)."""

    def __init__(self, rate_per_s: float, burst: int, *, clock: Callable[[], float] = time.monotonic,
                 max_keys: int = MAX_KEYS):
        if not math.isfinite(rate_per_s):
            raise ValueError(f"write rate must be a finite number per second, not {rate_per_s!r}")
        if rate_per_s > 0 and (not isinstance(burst, int) or burst < 1):
            raise ValueError(f"write burst must be a whole number >= 1, not {burst!r}")
        self.rate_per_s, self.burst = float(rate_per_s), int(burst)
        self.clock, self.max_keys = clock, max_keys
        self._buckets: OrderedDict[Hashable, _Bucket] = OrderedDict()
        self._lock = threading.Lock()

    @property
    def enabled(self) -> bool:
        return self.rate_per_s > 0

    def describe(self) -> str:
        return (f"{self.rate_per_s:g} writes/s per token, bursts of up to {self.burst}" if self.enabled
                else "no limit on writes")

    def take(self, key: Hashable) -> float:
        """Take one unit for ``key``: 0.0 when admitted, else the seconds until a unit
        is back (the request is refused; a refused request takes nothing)."""
        if not self.enabled:
            return 0.0
        now = self.clock()
        with self._lock:
            bucket = self._buckets.get(key)
            if bucket is None:
                bucket = self._buckets[key] = _Bucket(float(self.burst), now)
            else:
                self._buckets.move_to_end(key)
                bucket.level = min(float(self.burst), bucket.level + (now - bucket.at) * self.rate_per_s)
                bucket.at = now
            self._prune(now)
            if bucket.level >= 1.0:
                bucket.level -= 1.0
                return 0.0
            return (1.0 - bucket.level) / self.rate_per_s

    def transfer(self, old: Hashable, new: Hashable) -> None:
        """``new`` continues ``old``'s bucket (a rotated token's successor: a rotation
        does not buy a fresh burst)."""
        with self._lock:
            bucket = self._buckets.get(old)
            if bucket is not None:
                self._buckets[new] = _Bucket(bucket.level, bucket.at)

    def _prune(self, now: float) -> None:
        """Drop buckets that are full again from the least recently used end, and the
        oldest beyond ``max_keys``; stops at the first one still refilling."""
        refill_s = self.burst / self.rate_per_s
        while self._buckets:
            key, oldest = next(iter(self._buckets.items()))
            if len(self._buckets) > self.max_keys or now - oldest.at >= refill_s:
                del self._buckets[key]
            else:
                break

    def __len__(self) -> int:
        return len(self._buckets)


def retry_after_s(wait_s: float) -> int:
    """``Retry-After`` in whole seconds: rounded up, at least 1."""
    return max(1, math.ceil(wait_s))
