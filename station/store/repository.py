"""The results store: inspections, their characteristic results, image crops, events.

Rules this class keeps, and why:

* **Committed before reported.** Every public call is one transaction and returns only
  after its commit, so whatever the sequencer reports (to the MES, the panel) is
  already on disk.
* **Never half-written.** ``finish`` commits the last characteristics, the final state
  and its event together. A process killed at any point leaves the state before or
  after a call, never between (SQLite's atomic commit, WAL mode).
* **Crash recovery.** An inspection still ``running`` when its process died would
  stay running forever; :meth:`Store.open` (the station's way in) marks such
  inspections ``interrupted``, with a reason and an event. Only the owner of the
  data folder may do that: :meth:`Store.open` takes an exclusive lock on
  ``<data>/store.lock`` first (released by the OS when the process dies, even on
  SIGKILL), so a second station process is refused instead of interrupting the live
  one. Readers (CLI, reports) construct :class:`Store` directly: no lock, no recovery.
* **Final means final.** Characteristics and images are added only while the
  inspection runs; the event log is append-only.
* **One error type.** Database failures (locked, disk full, server gone) raise
  :class:`StoreUnavailable`, a :class:`StoreError`, with a message an operator can act on.
"""

from __future__ import annotations

import fcntl
import json
import math
import os
import re
import threading
import uuid
import zlib
from contextlib import contextmanager
from dataclasses import asdict, dataclass
from datetime import datetime
from pathlib import Path
from typing import Any, Iterable, Iterator, Mapping

from sqlalchemy import event as sa_event
from sqlalchemy import Connection, false, func, or_, select
from sqlalchemy.engine import make_url
from alembic.util.exc import CommandError
from sqlalchemy.exc import DBAPIError, IntegrityError, OperationalError, SQLAlchemyError
from sqlalchemy.orm import Session, selectinload, sessionmaker, undefer

from station.store import images as img
from station.store.engine import (
    ADVISORY_LOCK_CLASS,
    DEFAULT_BUSY_TIMEOUT_S,
    MIGRATION_LOCK_KEY,
    WRITE_OPTION,
    default_url,
    make_engine,
    sqlite_file,
)
from station.store.errors import (
    DuplicateIdempotencyKey,
    InspectionNotFound,
    InspectionStateError,
    StoreError,
    StoreIntegrityError,
    StoreLocked,
    StoreUnavailable,
)
from station.store.migrate import upgrade_engine
from station.store.models import (
    KEY_LEN,
    NAME_LEN,
    RESULTS,
    STATES,
    CharacteristicResult,
    Event,
    Finding,
    ImageCrop,
    Inspection,
    utcnow,
)
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

#: the data folder when none is given: relative to the working directory, as
#: ``var/`` of a checkout (ignored by git); a deployment passes its own
DEFAULT_DATA_DIR = Path("var")
#: states ``finish`` may set; ``interrupted`` belongs to recovery
FINISH_STATES = ("complete", "aborted", "faulted")
#: largest page ``list_inspections`` and ``events`` return, so a careless client
#: cannot make the station read its whole history at once
MAX_PAGE = 1000
LOCK_FILE = "store.lock"
#: event kinds are short identifiers (``state`` for every state change, ``alarm``, ``info`` ...)
EVENT_KIND_LEN = 32


class _StoreSession(Session):
    """Sessions of the store; the class carries the append-only guard below."""


@sa_event.listens_for(_StoreSession, "before_flush")
def _event_log_is_append_only(session: Session, _ctx, _instances) -> None:
    for obj in list(session.dirty) + list(session.deleted):
        if isinstance(obj, Event) and (obj in session.deleted or session.is_modified(obj)):
            raise StoreError("the event log is append-only: events are never changed or deleted")


def _check_text(name: str, value: str | None, max_len: int, *, required: bool = False) -> None:
    if value is None:
        if required:
            raise ValueError(f"{name} is required")
        return
    if not isinstance(value, str) or not value.strip() or len(value) > max_len or "\x00" in value:
        raise ValueError(f"{name} must be a non-blank string of at most {max_len} characters "
                         f"(no NUL), not {value!r}")


def _has_nul(*values) -> bool:
    """A lookup by a text with a NUL character finds nothing: no stored text has one
    (the store refuses them, and PostgreSQL cannot hold them), so it is not sent."""
    return any(isinstance(v, str) and "\x00" in v for v in values)


def finite_json(value: Any) -> Any:
    """A JSON document with every non-finite number as null: JSON has no NaN or
    infinity (PostgreSQL's JSONB refuses them; SQLite would keep a non-standard token),
    so the store keeps what any reader can parse, the same on both backends."""
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if isinstance(value, Mapping):
        return {k: finite_json(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [finite_json(v) for v in value]
    return value


def _json_document(name: str, value: Mapping[str, Any]) -> dict[str, Any]:
    """A document for a JSON column: a mapping of plain JSON (non-finite numbers as
    null, see :func:`finite_json`); ValueError for anything else, before any write."""
    if not isinstance(value, Mapping):
        raise ValueError(f"{name} must be a JSON object (a mapping), not {type(value).__name__}")
    doc = finite_json(_plain(dict(value)))
    try:
        json.dumps(doc, allow_nan=False)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{name} must be plain JSON (str, numbers, lists, dicts): {exc}") from None
    return doc


def _plain(value: Any) -> Any:
    """NumPy's scalars (a count or a size computed with numpy) as Python's numbers."""
    if isinstance(value, Mapping):
        return {k: _plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    item = getattr(value, "item", None)
    if item is not None and type(value).__module__ == "numpy" and getattr(value, "ndim", None) == 0:
        return item()
    return value


@dataclass(frozen=True)
class _StagedImage:
    """An image checked, encoded and written under a temporary name, to be recorded."""

    subject: str
    rel: str  # relative to the data folder, forward slashes
    digest: str
    final: Path
    tmp: Path


def _aware(name: str, t: datetime | None) -> None:
    if t is not None and (t.tzinfo is None or t.utcoffset() is None):
        raise ValueError(f"{name} must be an aware datetime (UTC or with an offset), not naive {t!r}")


class Store:
    """Repository of inspection results. See the module docstring for its rules.

    ``Store(url)`` opens the database for reading and writing (migrating it to the
    newest schema); the station process uses :meth:`Store.open`, which also takes the
    owner lock and recovers interrupted inspections.
    """

    def __init__(self, url: str | None = None, *, data_dir: str | Path = DEFAULT_DATA_DIR,
                 busy_timeout_s: float = DEFAULT_BUSY_TIMEOUT_S, migrate: bool = True,
                 station_id: str | None = None):
        check_station_id(station_id)
        #: stamped on every inspection and event this store writes (docs/plant.md);
        #: None for readers and for a single station that has none
        self.station_id = station_id
        self.data_dir = Path(data_dir).resolve()
        self.url = url or default_url(self.data_dir)
        self.busy_timeout_s = busy_timeout_s
        self.engine = make_engine(self.url, busy_timeout_s=busy_timeout_s)
        self._read_sessions = sessionmaker(self.engine, class_=_StoreSession, expire_on_commit=False)
        self._write_sessions = sessionmaker(self.engine.execution_options(**{WRITE_OPTION: True}),
                                            class_=_StoreSession, expire_on_commit=False)
        self._lock_fd: int | None = None
        self._owner_conn: Connection | None = None
        #: incremented after every committed change to an inspection's record (begin,
        #: characteristics, images, finish, recovery; not the event log). A reader that
        #: noted it before a read knows the record it read is current while it is
        #: unchanged (api/records.py caches on it). Writes by other processes are not
        #: counted: the process that owns the station is the only writer of inspections.
        self.record_generation = 0
        self._generation_lock = threading.Lock()  # the station's and the API's threads both write
        if migrate:
            try:
                self._guard("bring the database schema up to date", lambda: upgrade_engine(self.engine))
            except BaseException:
                self.engine.dispose()  # no half-open store left behind
                raise

    # -- life cycle ---------------------------------------------------------------------------

    @classmethod
    def open(cls, url: str | None = None, *, data_dir: str | Path = DEFAULT_DATA_DIR,
             busy_timeout_s: float = DEFAULT_BUSY_TIMEOUT_S, station_id: str | None = None) -> Store:
        """The station's store: migrated, owned by this process, recovered.

        Raises :class:`StoreLocked` when another process owns the data folder, or (on a
        shared server database) when another live process holds the same station id.
        """
        store = cls(url, data_dir=data_dir, busy_timeout_s=busy_timeout_s, station_id=station_id)
        try:
            store._acquire_owner_lock()
            store._acquire_station_lock()
            store.recover_interrupted()
        except BaseException:
            store.close()
            raise
        return store

    def close(self) -> None:
        """Release the owner locks and the connections (idempotent)."""
        if self._owner_conn is not None:
            try:
                self._owner_conn.close()  # ends the session: the server drops its advisory lock
            except SQLAlchemyError:
                pass  # the server is gone, and the lock with it
            self._owner_conn = None
        self.engine.dispose()
        if self._lock_fd is not None:
            os.close(self._lock_fd)  # closing the descriptor releases the flock
            self._lock_fd = None

    def __enter__(self) -> Store:
        return self

    def __exit__(self, *_exc) -> None:
        self.close()

    def _acquire_owner_lock(self) -> None:
        self.data_dir.mkdir(parents=True, exist_ok=True)
        path = self.data_dir / LOCK_FILE
        fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            os.close(fd)
            raise StoreLocked(f"{path}: another station process owns this data folder; "
                              "only one may run inspections on it") from None
        os.ftruncate(fd, 0)
        os.write(fd, f"{os.getpid()}\n".encode())  # for a person wondering who holds it
        self._lock_fd = fd

    def _acquire_station_lock(self) -> None:
        """On a server database shared by several stations (PostgreSQL), the right to
        recover a station's interrupted inspections belongs to the one live process with
        that station id: a session-level advisory lock keyed by the id, held on a
        connection of its own for the store's life. The server drops it when that
        session ends, however the process ended (SIGKILL, power cut: the connection
        closes). On SQLite the data folder's file lock is the owner lock."""
        if self.engine.dialect.name != "postgresql":
            return
        key = station_lock_key(self.station_id)
        conn = None
        try:
            conn = self.engine.connect()
            got = conn.exec_driver_sql(f"SELECT pg_try_advisory_lock({ADVISORY_LOCK_CLASS}, {key})").scalar()
            conn.commit()
        except (OperationalError, DBAPIError) as exc:
            if conn is not None:
                conn.close()
            raise StoreUnavailable(self._explain(exc, "take the station's lock")) from exc
        if not got:
            conn.close()
            raise StoreLocked(f"results store {self._where()}: another live station process has station id "
                              f"{self.station_id!r}; every station on a shared database needs its own id "
                              "([station] id in its config, or serve --station-id)")
        self._owner_conn = conn

    # -- transactions and errors --------------------------------------------------------------

    def _where(self) -> str:
        f = sqlite_file(self.url)
        return str(f) if f is not None else make_url(self.url).render_as_string(hide_password=True)

    def _explain(self, exc: DBAPIError, what: str) -> str:
        text = str(exc.orig) if exc.orig is not None else str(exc)
        low = text.lower()
        if "locked" in low or "busy" in low or "lock timeout" in low:
            why = (f"the database is locked by another process (waited {self.busy_timeout_s:g} s); "
                   "is a long report or a second station running?")
        elif "full" in low or "no space" in low:
            why = "the disk holding the database is full (free space, then retry)"
        elif "readonly" in low or "read-only" in low:
            why = ("the database is read-only (check the file's permissions; on a server, that this is "
                   "the primary and not a standby)")
        elif "unable to open" in low:
            why = "the database file cannot be opened (check the folder exists and is writable)"
        elif "connection" in low and ("refused" in low or "timeout" in low or "closed" in low or "failed" in low):
            why = f"the database server does not answer ({text.strip().splitlines()[0]}); is it running and reachable?"
        else:
            why = text
        return f"results store {self._where()}: cannot {what}: {why}"

    def _guard(self, what: str, fn):
        try:
            return fn()
        except IntegrityError as exc:
            raise StoreIntegrityError(f"results store: cannot {what}: {exc.orig}") from exc
        except (OperationalError, DBAPIError) as exc:
            raise StoreUnavailable(self._explain(exc, what)) from exc
        except CommandError as exc:
            # e.g. a database migrated by a newer station than this one
            raise StoreError(f"results store {self._where()}: cannot {what}: {exc}") from exc

    def _bump_records(self) -> None:
        """After a commit that changed an inspection's record (see ``record_generation``)."""
        with self._generation_lock:
            self.record_generation += 1

    @contextmanager
    def transaction(self, what: str, *, write: bool = True) -> Iterator[Session]:
        """One session, one transaction: committed at the end of the block, rolled back
        (nothing written) on any error; database errors become :class:`StoreError`."""
        factory = self._write_sessions if write else self._read_sessions
        try:
            with factory() as session, session.begin():
                yield session
        except IntegrityError as exc:
            raise StoreIntegrityError(f"results store: cannot {what}: {exc.orig}") from exc
        except (OperationalError, DBAPIError) as exc:
            raise StoreUnavailable(self._explain(exc, what)) from exc
        except SQLAlchemyError as exc:
            raise StoreError(f"results store {self._where()}: cannot {what}: {exc}") from exc

    @staticmethod
    def _running(session: Session, inspection_id: str, what: str) -> Inspection:
        """The inspection, locked for this transaction (``FOR UPDATE`` where the backend
        has it; SQLite's write transaction already excludes other writers)."""
        insp = session.get(Inspection, inspection_id, with_for_update=True)
        if insp is None:
            raise InspectionNotFound(f"no inspection {inspection_id!r}")
        if insp.state != "running":
            raise InspectionStateError(f"cannot {what}: inspection {inspection_id} is {insp.state}; "
                                       "its results are final")
        return insp

    # -- writing ------------------------------------------------------------------------------

    def begin_inspection(self, part_number: str, *, serial: str | None = None, order_id: str | None = None,
                         traceability: Traceability | Mapping[str, Any] | None = None,
                         idempotency_key: str | None = None, started_at: datetime | None = None,
                         inspection_id: str | None = None) -> str:
        """Create a ``running`` inspection and return its id (a UUID string; the
        caller's ``inspection_id`` when given: the inspection's documents carry it from
        their start, before the record exists).

        A repeated ``idempotency_key`` raises :class:`DuplicateIdempotencyKey` naming the
        inspection that has it, so the REST API can answer a retried POST with it.
        """
        _check_text("part_number", part_number, NAME_LEN, required=True)
        _check_text("serial", serial, NAME_LEN)
        _check_text("order_id", order_id, NAME_LEN)
        _check_text("idempotency_key", idempotency_key, KEY_LEN)
        _aware("started_at", started_at)
        if traceability is None:
            traceability = Traceability()
        trace = traceability.to_json() if isinstance(traceability, Traceability) else dict(traceability)
        try:
            json.dumps(trace, allow_nan=False)
        except (TypeError, ValueError) as exc:
            raise ValueError(f"traceability must be plain JSON (str, numbers, lists, dicts): {exc}") from None
        if inspection_id is None:
            inspection_id = str(uuid.uuid4())
        else:
            try:
                inspection_id = str(uuid.UUID(inspection_id))
            except (ValueError, AttributeError, TypeError):
                raise ValueError(f"inspection_id must be a UUID, not {inspection_id!r}") from None
        try:
            with self.transaction("begin an inspection") as s:
                s.add(Inspection(
                    id=inspection_id, station_id=self.station_id, part_number=part_number, serial=serial, order_id=order_id,
                    state="running", result=None, reason=None, started_at=started_at or utcnow(),
                    finished_at=None, traceability=trace, idempotency_key=idempotency_key,
                ))
                s.flush()  # the inspection row first: the event refers to it
                s.add(Event(inspection_id=inspection_id, station_id=self.station_id, at=utcnow(), kind="state",
                            message=f"running: part {part_number}" + (f", serial {serial}" if serial else "")))
            self._bump_records()
        except StoreIntegrityError:
            if idempotency_key is not None:
                existing = self.find_by_idempotency_key(idempotency_key)
                if existing is not None:
                    raise DuplicateIdempotencyKey(idempotency_key, existing) from None
            raise
        return inspection_id

    def record_characteristic(self, inspection_id: str, measurement: Measurement) -> None:
        """Commit one characteristic result of a running inspection."""
        self.record_characteristics(inspection_id, [measurement])

    def record_characteristics(self, inspection_id: str, measurements: Iterable[Measurement]) -> None:
        """Commit several characteristic results of a running inspection, all or none."""
        items = list(measurements)
        with self.transaction("record characteristic results") as s:
            self._running(s, inspection_id, "record characteristic results")
            self._add_measurements(s, inspection_id, items)
        self._bump_records()

    @staticmethod
    def _add_measurements(s: Session, inspection_id: str, items: list[Measurement]) -> None:
        for m in items:
            if not isinstance(m, Measurement):
                raise TypeError(f"expected a Measurement, not {type(m).__name__}")
        ids = [m.characteristic_id for m in items]
        have = set(s.scalars(select(CharacteristicResult.characteristic_id)
                             .where(CharacteristicResult.inspection_id == inspection_id)))
        dup = sorted({i for i in ids if i in have or ids.count(i) > 1})
        if dup:
            raise StoreIntegrityError(f"inspection {inspection_id} already has a result for {', '.join(dup)}; "
                                      "a characteristic is recorded once")
        for m in items:
            # Measurement's fields are the columns' names, one to one
            s.add(CharacteristicResult(inspection_id=inspection_id, **asdict(m)))

    def add_image(self, inspection_id: str, subject: str, name: str, image) -> ImageRecord:
        """Save a crop (numpy uint8) as ``<data>/images/<inspection id>/<name>.png`` and
        record its relative path and SHA-256.

        The file is written under a temporary name first and renamed into place inside
        the transaction that records it, after the checks: a crop already recorded is
        never overwritten, and a failed call leaves no file behind (a kill between the
        rename and the commit can leave an unrecorded file, never a record without one).
        """
        staged = self._stage_image(inspection_id, subject, name, image)
        try:
            with self.transaction("record an image crop") as s:
                self._running(s, inspection_id, "add an image")
                record = self._record_image(s, inspection_id, staged)
                s.flush()
                self._publish_image(staged)
        finally:
            staged.tmp.unlink(missing_ok=True)  # still there only when the record was not made
        self._bump_records()
        return record

    def _stage_image(self, inspection_id: str, subject: str, name: str, image) -> _StagedImage:
        """Check, encode and write an image under a temporary name beside its place (the
        first half of :meth:`add_image`); the caller records it, publishes it inside the
        same transaction and unlinks the temporary file in any case."""
        _check_text("subject", subject, NAME_LEN, required=True)
        rel = img.crop_relpath(inspection_id, name)
        data = img.encode_png(image)
        digest = img.sha256_hex(data)
        final = self.data_dir / Path(*rel.parts)
        # belt and braces: whatever the name check missed, the file stays under images/
        if not final.resolve().is_relative_to((self.data_dir / img.IMAGES_DIR).resolve()):
            raise ValueError(f"image name {name!r} refused: it would leave {self.data_dir / img.IMAGES_DIR}")
        try:
            tmp = img.write_temp(final, data)
        except OSError as exc:
            raise StoreUnavailable(f"results store: cannot write image {final}: {exc.strerror or exc}") from exc
        return _StagedImage(subject, str(rel), digest, final, tmp)

    @staticmethod
    def _record_image(s: Session, inspection_id: str, staged: _StagedImage) -> ImageRecord:
        if s.scalar(select(ImageCrop.id).where(ImageCrop.path == staged.rel)) is not None:
            raise StoreIntegrityError(f"inspection {inspection_id} already has an image {staged.final.name}")
        created = utcnow()
        s.add(ImageCrop(inspection_id=inspection_id, subject=staged.subject, path=staged.rel,
                        sha256=staged.digest, created_at=created))
        return ImageRecord(staged.subject, staged.rel, staged.digest, created)

    @staticmethod
    def _publish_image(staged: _StagedImage) -> None:
        """Rename a staged image into place: inside its transaction, after every
        statement of it has run (only the COMMIT left)."""
        try:
            img.publish(staged.tmp, staged.final)
        except OSError as exc:
            raise StoreUnavailable(f"results store: cannot write image {staged.final}: "
                                   f"{exc.strerror or exc}") from exc

    def finish(self, inspection_id: str, state: str, result: str | None = None, reason: str | None = None, *,
               measurements: Iterable[Measurement] = (), findings: Iterable[FindingRecord] = (),
               machine_s: float | None = None, cycle: Mapping[str, Any] | None = None,
               surface: Mapping[str, Any] | None = None,
               images: Iterable[tuple[str, str, Any]] = ()) -> InspectionRecord:
        """End a running inspection: the given characteristics and findings, the final
        state, the verdict, the machine time, the surface document, the images and a
        state event, committed together.

        ``state`` is ``complete`` (``result`` then ``pass`` or ``fail``), ``aborted`` or
        ``faulted`` (no result). A ``pass`` needs at least one characteristic and no
        failed one: a contradiction there is a bug upstream, refused with ValueError
        and nothing written. ``surface``: the whole-surface inspection's document
        (plain JSON; a non-finite number is kept as null). ``images``: ``(subject, name,
        uint8 array)`` each, saved as :meth:`add_image` saves one (the surface's picture:
        subject and name ``surface``), their files renamed into place after every
        statement of the transaction has run, just before its commit. Returns the
        inspection as stored.
        """
        if state not in FINISH_STATES:
            raise ValueError(f"finish state must be one of {', '.join(FINISH_STATES)}, not {state!r}")
        if state == "complete" and result not in RESULTS:
            raise ValueError(f"a complete inspection needs result 'pass' or 'fail', not {result!r}")
        if state != "complete" and result is not None:
            raise ValueError(f"an inspection that is {state} has no result (got {result!r})")
        items = list(measurements)
        found = list(findings)
        for f in found:
            if not isinstance(f, FindingRecord):
                raise TypeError(f"expected a FindingRecord, not {type(f).__name__}")
        if machine_s is not None and (isinstance(machine_s, bool) or not isinstance(machine_s, (int, float))
                                      or not math.isfinite(machine_s) or machine_s < 0):
            raise ValueError(f"machine_s must be a finite number >= 0 or None, not {machine_s!r}")
        surface_doc = None if surface is None else _json_document("surface", surface)
        pictures = list(images)
        for p in pictures:
            if not (isinstance(p, tuple) and len(p) == 3):
                raise TypeError(f"an image to store is (subject, name, uint8 array), not {type(p).__name__}")
        staged: list[_StagedImage] = []
        try:
            for subject, name, image in pictures:  # checked and written aside before the transaction
                staged.append(self._stage_image(inspection_id, subject, name, image))
            with self.transaction("finish the inspection") as s:
                insp = self._running(s, inspection_id, "finish")
                self._add_measurements(s, inspection_id, items)
                for f in found:
                    s.add(Finding(inspection_id=inspection_id, **asdict(f)))
                if machine_s is not None:
                    insp.machine_s = float(machine_s)
                    insp.cycle = None if cycle is None else finite_json(dict(cycle))
                if surface_doc is not None:
                    insp.surface = surface_doc
                for st in staged:
                    self._record_image(s, inspection_id, st)
                s.flush()
                if result == "pass":
                    verdicts = s.scalars(select(CharacteristicResult.passed)
                                         .where(CharacteristicResult.inspection_id == inspection_id)).all()
                    n_all, n_failed = len(verdicts), verdicts.count(False)
                    if n_all == 0 or n_failed:
                        raise ValueError(f"inspection {inspection_id}: a pass needs characteristics that all "
                                         f"passed ({n_all} recorded, {n_failed} failed)")
                insp.state, insp.result, insp.reason, insp.finished_at = state, result, reason, utcnow()
                s.add(Event(inspection_id=inspection_id, station_id=self.station_id, at=utcnow(), kind="state",
                            message=f"{state}" + (f": {result}" if result else "")
                            + (f" ({reason})" if reason else "")))
                # every statement has run (a full disk, a broken constraint: raised here,
                # no file published); then the pictures go into place, and the commit
                s.flush()
                for st in staged:
                    self._publish_image(st)
        finally:
            for st in staged:
                st.tmp.unlink(missing_ok=True)  # still there only when the record was not made
        self._bump_records()
        return self.get(inspection_id)

    def recover_interrupted(self, reason: str | None = None) -> list[str]:
        """Mark every ``running`` inspection of this station ``interrupted`` (with a
        reason and an event) and return their ids. Call only from the process that owns
        the store (:meth:`open` does): a running inspection of a live process would be
        cut off. With a station id, only that station's inspections (and those older
        than station ids) are this process's to recover; without one, all are."""
        reason = reason or (f"the station process stopped before the inspection finished "
                            f"(found running when process {os.getpid()} opened the store)")
        with self.transaction("recover interrupted inspections") as s:
            q = select(Inspection).where(Inspection.state == "running")
            if self.station_id is not None:
                q = q.where(or_(Inspection.station_id == self.station_id, Inspection.station_id.is_(None)))
            stale = s.scalars(q.with_for_update()).all()
            now = utcnow()
            for insp in stale:
                insp.state, insp.result, insp.reason, insp.finished_at = "interrupted", None, reason, now
                s.add(Event(inspection_id=insp.id, station_id=self.station_id, at=now, kind="state",
                            message=f"interrupted: {reason}"))
            ids = [i.id for i in stale]
        self._bump_records()
        return ids

    def log_event(self, kind: str, message: str, inspection_id: str | None = None, *,
                  at: datetime | None = None) -> EventRecord:
        """Append an event (an alarm, a state change of the station) to the log. ``at``:
        when it happened (an aware datetime), for an event written after the fact; now
        by default."""
        _check_text("kind", kind, EVENT_KIND_LEN, required=True)
        if not isinstance(message, str):
            raise ValueError(f"message must be a string, not {type(message).__name__}")
        if at is not None and (not isinstance(at, datetime) or at.tzinfo is None or at.utcoffset() is None):
            raise ValueError(f"at must be an aware datetime, not {at!r}")
        with self.transaction("log an event") as s:
            if inspection_id is not None and s.get(Inspection, inspection_id) is None:
                raise InspectionNotFound(f"no inspection {inspection_id!r}")
            ev = Event(inspection_id=inspection_id, station_id=self.station_id, at=at or utcnow(), kind=kind,
                       message=message)
            s.add(ev)
            s.flush()
            return _event_record(ev)

    # -- reading ------------------------------------------------------------------------------

    def get(self, inspection_id: str) -> InspectionRecord:
        """An inspection with its characteristics and images; :class:`InspectionNotFound`."""
        if _has_nul(inspection_id):
            raise InspectionNotFound(f"no inspection {inspection_id!r}")
        with self.transaction("read an inspection", write=False) as s:
            insp = s.scalar(select(Inspection).where(Inspection.id == inspection_id)
                            .options(undefer(Inspection.surface),
                                     selectinload(Inspection.characteristics), selectinload(Inspection.images),
                                     selectinload(Inspection.findings)))
            if insp is None:
                raise InspectionNotFound(f"no inspection {inspection_id!r}")
            return InspectionRecord(
                **_summary_fields(insp),
                characteristics=tuple(CharacteristicRecord(
                    c.characteristic_id, c.unit, c.nominal, c.lower_limit, c.upper_limit, c.measured,
                    c.uncertainty_k2, c.passed, c.true_value) for c in insp.characteristics),
                images=tuple(ImageRecord(i.subject, i.path, i.sha256, i.created_at) for i in insp.images),
                findings=tuple(FindingRecord(f.kind, f.message, f.subject, f.axial_mm, f.angle_deg, f.diameter_mm,
                                             f.u_mm) for f in insp.findings),
                surface=None if insp.surface is None else dict(insp.surface),
            )

    def find_by_idempotency_key(self, key: str) -> str | None:
        if _has_nul(key):
            return None
        with self.transaction("look up an idempotency key", write=False) as s:
            return s.scalar(select(Inspection.id).where(Inspection.idempotency_key == key))

    @staticmethod
    def _filters(since, until, part_number, serial, result, state, station=None) -> list:
        _aware("since", since)
        _aware("until", until)
        if result is not None and result not in RESULTS:
            raise ValueError(f"result filter must be one of {', '.join(RESULTS)}, not {result!r}")
        if state is not None and state not in STATES:
            raise ValueError(f"state filter must be one of {', '.join(STATES)}, not {state!r}")
        conds = []
        if since is not None:
            conds.append(Inspection.started_at >= since)
        if until is not None:
            conds.append(Inspection.started_at < until)
        if _has_nul(part_number, serial, station):
            return [false()]
        for column, value in ((Inspection.part_number, part_number), (Inspection.serial, serial),
                              (Inspection.result, result), (Inspection.state, state),
                              (Inspection.station_id, station)):
            if value is not None:
                conds.append(column == value)
        return conds

    def list_inspections(self, *, since: datetime | None = None, until: datetime | None = None,
                         part_number: str | None = None, serial: str | None = None, result: str | None = None,
                         state: str | None = None, station: str | None = None, limit: int = 50,
                         offset: int = 0) -> list[InspectionSummary]:
        """Inspections newest first (by start time), filtered (``station``: one
        station's id); ``since`` is inclusive, ``until`` exclusive. Page with ``limit``
        (1..1000) and ``offset``."""
        if not 1 <= limit <= MAX_PAGE or offset < 0:
            raise ValueError(f"limit must be 1..{MAX_PAGE} and offset >= 0 (got {limit}, {offset})")
        conds = self._filters(since, until, part_number, serial, result, state, station)
        with self.transaction("list inspections", write=False) as s:
            rows = s.scalars(select(Inspection).where(*conds)
                             # id breaks ties of equal start times, so pages never overlap
                             .order_by(Inspection.started_at.desc(), Inspection.id.desc())
                             .limit(limit).offset(offset)).all()
            return [InspectionSummary(**_summary_fields(r)) for r in rows]

    def count_inspections(self, *, since: datetime | None = None, until: datetime | None = None,
                          part_number: str | None = None, serial: str | None = None, result: str | None = None,
                          state: str | None = None, station: str | None = None) -> int:
        """How many inspections :meth:`list_inspections` would page through."""
        conds = self._filters(since, until, part_number, serial, result, state, station)
        with self.transaction("count inspections", write=False) as s:
            return s.scalar(select(func.count()).select_from(Inspection).where(*conds))

    def stations(self) -> list[str]:
        """The ids of the stations that have written inspections here, sorted."""
        with self.transaction("list stations", write=False) as s:
            return sorted(s.scalars(select(Inspection.station_id).where(Inspection.station_id.is_not(None))
                                    .distinct()))

    def events(self, inspection_id: str | None = None, *, kind: str | None = None, limit: int = 100,
               offset: int = 0, newest_first: bool = False, station: str | None = None,
               with_unassigned: bool = False) -> list[EventRecord]:
        """Events in the order they were logged (or newest first), of one inspection or
        all (``station``: of one station; ``with_unassigned``: and those logged before
        stations had ids, which a station upgraded in place counts as its own)."""
        if not 1 <= limit <= MAX_PAGE or offset < 0:
            raise ValueError(f"limit must be 1..{MAX_PAGE} and offset >= 0 (got {limit}, {offset})")
        q = select(Event)
        if _has_nul(inspection_id, kind, station):
            return []
        if station is not None:
            q = q.where(or_(Event.station_id == station, Event.station_id.is_(None)) if with_unassigned
                        else Event.station_id == station)
        if inspection_id is not None:
            q = q.where(Event.inspection_id == inspection_id)
        if kind is not None:
            q = q.where(Event.kind == kind)
        q = q.order_by(Event.id.desc() if newest_first else Event.id.asc()).limit(limit).offset(offset)
        with self.transaction("read events", write=False) as s:
            return [_event_record(e) for e in s.scalars(q)]

    def image_path(self, record: ImageRecord) -> Path:
        """Where an image crop is on disk."""
        return self.data_dir / Path(*record.path.split("/"))


def _summary_fields(insp: Inspection) -> dict[str, Any]:
    return dict(id=insp.id, part_number=insp.part_number, serial=insp.serial, order_id=insp.order_id,
                state=insp.state, result=insp.result, reason=insp.reason, started_at=insp.started_at,
                finished_at=insp.finished_at, traceability=dict(insp.traceability or {}),
                idempotency_key=insp.idempotency_key, machine_s=insp.machine_s,
                cycle=None if insp.cycle is None else dict(insp.cycle), station_id=insp.station_id)


def _event_record(e: Event) -> EventRecord:
    return EventRecord(e.id, e.inspection_id, e.at, e.kind, e.message, e.station_id)


_STATION_ID = re.compile(r"[A-Za-z0-9][A-Za-z0-9._-]{0,63}")


def check_station_id(station_id: str | None) -> None:
    """A station id is 1-64 letters, digits, '.', '_' or '-' (it appears in URLs,
    file names and OPC UA node names), starting with a letter or digit."""
    if station_id is not None and (not isinstance(station_id, str) or not _STATION_ID.fullmatch(station_id)):
        raise ValueError(f"station id must be 1-64 letters, digits, '.', '_' or '-' starting with a letter "
                         f"or digit, not {station_id!r}")


def station_lock_key(station_id: str | None) -> int:
    """The advisory lock's second key for a station id: a signed 32-bit CRC, never
    the migration lock's key (a CRC of 0 moves to 1)."""
    crc = zlib.crc32((station_id or "").encode())
    key = crc - (1 << 32) if crc >= (1 << 31) else crc
    return key if key != MIGRATION_LOCK_KEY else 1

