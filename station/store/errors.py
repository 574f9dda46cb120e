"""Errors of the results store.

Every failure of the store is a :class:`StoreError`, so the sequencer can catch one
type and raise an alarm with its message. The subclasses say what kind of failure it
is, for callers (the REST API) that answer differently to each.
"""

from __future__ import annotations


class StoreError(Exception):
    """The store could not do what was asked; the message says what and why."""


class StoreUnavailable(StoreError):
    """The database could not be written or read (locked by another process, disk
    full, file unreadable, server gone). Nothing of the failed call was committed."""


class StoreIntegrityError(StoreError):
    """The change would break a rule of the schema (a duplicate, a missing parent).
    Nothing of the failed call was committed."""


class InspectionNotFound(StoreError, LookupError):
    """No inspection has that id."""


class InspectionStateError(StoreError):
    """The inspection is not in a state that allows the call (results of a finished
    inspection are final)."""


class DuplicateIdempotencyKey(StoreError):
    """An inspection with that idempotency key exists already; ``inspection_id`` is it."""

    def __init__(self, key: str, inspection_id: str):
        self.key, self.inspection_id = key, inspection_id
        super().__init__(f"idempotency key {key!r} was already used by inspection {inspection_id}")


class StoreLocked(StoreError):
    """Another process holds the store's owner lock (only one station process may
    run inspections on a data folder)."""
