"""The results store: every inspection, its characteristic results, image crops and
the event log, in SQLite by default or PostgreSQL by URL.

    store = Store.open(data_dir="var")            # the station: migrate, own, recover
    iid = store.begin_inspection("ZDZG-22.2-12.3851", serial="A123")
    store.record_characteristic(iid, Measurement.of(spec.characteristic("hole_1.diameter"), 0.675, passed=True))
    store.finish(iid, "complete", "pass")

Schema, guarantees and recovery: ``docs/store.md``.
"""

from station.store.errors import (
    DuplicateIdempotencyKey,
    InspectionNotFound,
    InspectionStateError,
    StoreError,
    StoreIntegrityError,
    StoreLocked,
    StoreUnavailable,
)
from station.store.migrate import upgrade_to_head
from station.store.records import (
    CharacteristicRecord,
    EventRecord,
    FindingRecord,
    ImageRecord,
    InspectionRecord,
    InspectionSummary,
    Measurement,
    Traceability,
)
from station.store.repository import DEFAULT_DATA_DIR, FINISH_STATES, Store

__all__ = [
    "CharacteristicRecord", "DEFAULT_DATA_DIR", "DuplicateIdempotencyKey", "EventRecord", "FINISH_STATES", "FindingRecord",
    "ImageRecord", "InspectionNotFound", "InspectionRecord", "InspectionStateError", "InspectionSummary",
    "Measurement", "Store", "StoreError", "StoreIntegrityError", "StoreLocked", "StoreUnavailable",
    "Traceability", "upgrade_to_head",
]
