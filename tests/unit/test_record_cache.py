"""The API's inspection-record cache serves a record only while no commit has landed
since it was read (api/records.py)."""

from __future__ import annotations

import asyncio

from api.records import RecordCache


class FakeStore:
    def __init__(self):
        self.record_generation = 0
        self.state = "running"
        self.reads = 0
        self.during_read = None  # a commit that lands while a read is in flight

    def get(self, iid):
        self.reads += 1
        seen = self.state
        if self.during_read:
            self.during_read()
            self.during_read = None
        return (iid, seen)


async def direct(fn, iid):
    await asyncio.sleep(0)
    return fn(iid)


def commit(store, state):
    store.state = state
    store.record_generation += 1


def test_reads_once_per_commit_and_never_serves_an_older_record():
    async def go():
        store = FakeStore()
        cache = RecordCache(store, direct)
        got = await asyncio.gather(*(cache.get("a") for _ in range(50)))  # concurrent: one read
        assert store.reads == 1 and set(got) == {("a", "running")}
        assert await cache.get("a") == ("a", "running") and store.reads == 1  # kept
        commit(store, "complete")
        assert await cache.get("a") == ("a", "complete") and store.reads == 2
        # a commit during a read: that read's (older) answer is not served afterwards
        commit(store, "x1")
        store.during_read = lambda: commit(store, "x2")
        first = await cache.get("a")
        assert first == ("a", "x1")
        assert await cache.get("a") == ("a", "x2")
        assert store.reads == 4
        assert cache.hits >= 1
        return cache

    cache = asyncio.run(go())
    assert cache.misses >= 3


def test_not_found_is_not_cached():
    class Missing(FakeStore):
        def get(self, iid):
            self.reads += 1
            raise KeyError(iid)

    async def go():
        store = Missing()
        cache = RecordCache(store, direct)
        for _ in range(2):
            try:
                await cache.get("nope")
            except KeyError:
                pass
            else:
                raise AssertionError("expected KeyError")
        return store.reads

    assert asyncio.run(go()) == 2


def test_the_store_counts_every_change_of_a_record_and_nothing_else(tmp_path):
    import numpy as np

    from station.store import Measurement, Store

    with Store(data_dir=tmp_path) as store:
        seen = [store.record_generation]

        def changed():
            seen.append(store.record_generation)
            return seen[-1] > seen[-2]

        iid = store.begin_inspection("P-1", serial="S")
        assert changed()
        store.log_event("note", "an event is not part of the record", iid)
        assert not changed()
        store.record_characteristic(iid, Measurement("c", 1.0, 0.5, 1.5, 1.0, True))
        assert changed()
        store.add_image(iid, "hole_1", "hole_1", np.zeros((8, 8), np.uint8))
        assert changed()
        store.get(iid)
        assert not changed()
        store.finish(iid, "complete", "pass")
        assert changed()
        other = store.begin_inspection("P-1", serial="T")
        assert changed()
        assert store.recover_interrupted() == [other]
        assert changed()
