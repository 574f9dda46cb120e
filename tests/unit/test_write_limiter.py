"""The per-token limit on writes (api/ratelimit.py), with a clock of the test's own:
a burst, then the refill rate; a refused write takes nothing; the wait it names is
when a unit is back; tokens do not share a bucket; idle buckets are dropped, so the
table stays small; concurrent takes admit exactly the burst."""

from __future__ import annotations

import threading

import pytest

from api.ratelimit import WriteLimiter, retry_after_s


class Clock:
    def __init__(self) -> None:
        self.t = 1000.0

    def __call__(self) -> float:
        return self.t


def limiter(rate: float = 2.0, burst: int = 5, **kw) -> tuple[WriteLimiter, Clock]:
    clock = Clock()
    return WriteLimiter(rate, burst, clock=clock, **kw), clock


def test_a_burst_then_the_rate():
    lim, clock = limiter(rate=2.0, burst=5)
    assert [lim.take("a") for _ in range(5)] == [0.0] * 5
    assert lim.take("a") == pytest.approx(0.5)  # empty: one unit back in 1/rate
    clock.t += 0.25
    assert lim.take("a") == pytest.approx(0.25)  # half a unit back: the rest of the wait
    clock.t += 0.25
    assert lim.take("a") == 0.0
    assert lim.take("a") == pytest.approx(0.5)
    clock.t += 10.0  # a long pause refills to the burst, no further
    assert [lim.take("a") for _ in range(6)].count(0.0) == 5


def test_a_refused_write_takes_nothing():
    lim, clock = limiter(rate=1.0, burst=1)
    assert lim.take("a") == 0.0
    for _ in range(100):  # hammering while empty does not push the next admission back
        assert lim.take("a") == pytest.approx(1.0)
    clock.t += 1.0
    assert lim.take("a") == 0.0


def test_the_sustained_rate_is_the_configured_one():
    lim, clock = limiter(rate=5.0, burst=20)
    admitted = 0
    for _ in range(10_000):  # 100 s of a client trying every 10 ms
        admitted += lim.take("flood") == 0.0
        clock.t += 0.01
    assert admitted == pytest.approx(20 + 5.0 * 100, abs=2)


def test_tokens_have_buckets_of_their_own():
    lim, _ = limiter(rate=1.0, burst=3)
    for _ in range(3):
        lim.take(1)
    assert lim.take(1) > 0
    assert lim.take(2) == 0.0


def test_retry_after_is_whole_seconds_rounded_up_at_least_one():
    assert retry_after_s(0.001) == 1
    assert retry_after_s(0.5) == 1
    assert retry_after_s(1.0) == 1
    assert retry_after_s(1.01) == 2
    assert retry_after_s(59.2) == 60


def test_a_slow_rate_names_a_long_wait():
    lim, _ = limiter(rate=0.1, burst=1)
    lim.take("a")
    assert retry_after_s(lim.take("a")) == 10


def test_idle_buckets_are_dropped_and_the_table_is_bounded():
    lim, clock = limiter(rate=1.0, burst=10)
    for key in range(100):
        lim.take(key)
    assert len(lim) == 100
    clock.t += 10.0  # long enough for every bucket to be full again: same as none
    lim.take("new")
    assert len(lim) == 1
    lim2, _ = limiter(rate=1.0, burst=10, max_keys=50)
    for key in range(1000):
        lim2.take(key)
    assert len(lim2) == 50


def test_a_bucket_still_refilling_is_kept():
    lim, clock = limiter(rate=1.0, burst=10)
    for _ in range(10):
        lim.take("busy")
    clock.t += 5.0  # half refilled
    lim.take("other")
    assert lim.take("busy") == 0.0 and len(lim) == 2
    for _ in range(5):
        lim.take("busy")
    assert lim.take("busy") > 0  # the 5 units it had, not a fresh 10


def test_a_successor_continues_its_predecessors_bucket():
    lim, _ = limiter(rate=1.0, burst=3)
    for _ in range(3):
        lim.take("old")
    lim.transfer("old", "new")
    assert lim.take("new") > 0


def test_zero_rate_turns_the_limit_off():
    lim, _ = limiter(rate=0.0, burst=0)
    assert not lim.enabled and lim.describe() == "no limit on writes"
    assert all(lim.take("a") == 0.0 for _ in range(10_000))
    assert len(lim) == 0


def test_bad_settings_are_refused():
    with pytest.raises(ValueError, match="burst"):
        WriteLimiter(5.0, 0)
    with pytest.raises(ValueError, match="rate"):
        WriteLimiter(float("nan"), 10)


def test_concurrent_writes_admit_exactly_the_burst():
    lim = WriteLimiter(1e-6, 50)  # practically no refill during the test
    admitted = []
    start = threading.Barrier(8)

    def worker():
        start.wait()
        admitted.append(sum(lim.take("shared") == 0.0 for _ in range(100)))

    threads = [threading.Thread(target=worker) for _ in range(8)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert sum(admitted) == 50
