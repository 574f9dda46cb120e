"""The results store's tables, as SQLAlchemy 2.x ORM classes.

The schema is owned by the Alembic migrations in ``station/store/migrations``; these
classes must describe exactly the same schema (a test compares them). Change both
together: a new revision for every change to this file.

Portability: only generic types, so the same schema works on SQLite and PostgreSQL.
Timestamps go through :class:`UTCDateTime`, which refuses naive datetimes and gives
back aware UTC ones on every backend (SQLite has no time-zone type).
"""

from __future__ import annotations

from datetime import datetime, timezone
from typing import Any

from sqlalchemy import (
    JSON,
    Boolean,
    CheckConstraint,
    DateTime,
    Float,
    ForeignKey,
    Index,
    Integer,
    MetaData,
    String,
    Text,
    UniqueConstraint,
)
from sqlalchemy.dialects.postgresql import JSONB
from sqlalchemy.orm import DeclarativeBase, Mapped, mapped_column, relationship
from sqlalchemy.types import TypeDecorator

#: inspection life cycle: ``running`` until finished; ``interrupted`` is set only by
#: recovery, for inspections a previous process left running
STATES = ("running", "complete", "aborted", "faulted", "interrupted")
FINAL_STATES = STATES[1:]
RESULTS = ("pass", "fail")

#: lengths of identifying strings; generous, and bounded so that PostgreSQL gets
#: indexable VARCHARs (SQLite ignores the length)
ID_LEN = 36  # a UUID in its canonical text form
NAME_LEN = 64  # part numbers, serials, order ids, characteristic ids
KEY_LEN = 128  # idempotency keys chosen by the MES
PATH_LEN = 512  # image paths relative to the data folder
SHA256_HEX_LEN = 64

#: constraint names follow one convention so migrations can refer to them by name
NAMING_CONVENTION = {
    "ix": "ix_%(table_name)s_%(column_0_N_name)s",
    "uq": "uq_%(table_name)s_%(column_0_N_name)s",
    "ck": "ck_%(table_name)s_%(constraint_name)s",
    "fk": "fk_%(table_name)s_%(column_0_name)s_%(referred_table_name)s",
    "pk": "pk_%(table_name)s",
}

#: JSON on SQLite, JSONB on PostgreSQL (indexable, compact); same Python values
JSONDocument = JSON().with_variant(JSONB(), "postgresql")


class UTCDateTime(TypeDecorator):
    """An aware UTC datetime on every backend.

    Binding a naive datetime is a programming error (whose local time would it be?),
    so it raises. SQLite stores naive UTC text; PostgreSQL a ``timestamptz``.
    """

    impl = DateTime(timezone=True)
    cache_ok = True

    def process_bind_param(self, value: datetime | None, dialect) -> datetime | None:
        if value is None:
            return None
        if value.tzinfo is None or value.utcoffset() is None:
            raise ValueError(f"naive datetime {value!r}: the store keeps aware UTC times")
        value = value.astimezone(timezone.utc)
        return value.replace(tzinfo=None) if dialect.name == "sqlite" else value

    def process_result_value(self, value: datetime | None, dialect) -> datetime | None:
        if value is None:
            return None
        if value.tzinfo is None:
            return value.replace(tzinfo=timezone.utc)
        return value.astimezone(timezone.utc)


def utcnow() -> datetime:
    return datetime.now(timezone.utc)


class Base(DeclarativeBase):
    metadata = MetaData(naming_convention=NAMING_CONVENTION)


def _in(column: str, values: tuple[str, ...]) -> str:
    return f"{column} IN ({', '.join(repr(v) for v in values)})"


class Inspection(Base):
    """One inspection of one part: who, what, when, the verdict and how it was made."""

    __tablename__ = "inspection"

    id: Mapped[str] = mapped_column(String(ID_LEN), primary_key=True)
    #: the station that made it (its config's ``station_id``); None for records written
    #: before stations had ids (migration 0004)
    station_id: Mapped[str | None] = mapped_column(String(NAME_LEN))
    part_number: Mapped[str] = mapped_column(String(NAME_LEN))
    serial: Mapped[str | None] = mapped_column(String(NAME_LEN))
    order_id: Mapped[str | None] = mapped_column(String(NAME_LEN))
    state: Mapped[str] = mapped_column(String(16))
    result: Mapped[str | None] = mapped_column(String(8))
    reason: Mapped[str | None] = mapped_column(Text)
    started_at: Mapped[datetime] = mapped_column(UTCDateTime())
    finished_at: Mapped[datetime | None] = mapped_column(UTCDateTime())
    #: software version, model and compensation versions, calibration id, config hash, scenario
    traceability: Mapped[dict[str, Any]] = mapped_column(JSONDocument)
    #: chosen by the MES for a retried POST; unique where given (NULLs never collide)
    idempotency_key: Mapped[str | None] = mapped_column(String(KEY_LEN), unique=True)
    #: machine time of the inspection (s): the plan at the axes' real speeds, camera and
    #: vision included (docs/inspection.md, Cycle time); None until finished, or unknown
    machine_s: Mapped[float | None] = mapped_column(Float)
    #: how ``machine_s`` divides (moves, settle, frames, vision, other, in s) and its basis
    #: ("measured" on hardware; "modelled" under a twin's time scale)
    cycle: Mapped[dict[str, Any] | None] = mapped_column(JSONDocument)
    #: the whole-surface inspection (``station.inspection.surface.SurfaceResult.to_json``:
    #: defects, the unrolled picture's meta, coverage); None when the part spec asks for
    #: none or the inspection did not complete. Its picture is an image of the record,
    #: subject ``surface`` (migration 0006)
    surface: Mapped[dict[str, Any] | None] = mapped_column(JSONDocument, deferred=True)

    characteristics: Mapped[list[CharacteristicResult]] = relationship(
        back_populates="inspection", order_by="CharacteristicResult.id")
    images: Mapped[list[ImageCrop]] = relationship(back_populates="inspection", order_by="ImageCrop.id")
    findings: Mapped[list[Finding]] = relationship(back_populates="inspection", order_by="Finding.id")

    __table_args__ = (
        CheckConstraint(_in("state", STATES), name="state"),
        CheckConstraint(f"result IS NULL OR {_in('result', RESULTS)}", name="result"),
        # a verdict exists exactly for a complete inspection
        CheckConstraint("(state = 'complete') = (result IS NOT NULL)", name="result_iff_complete"),
        # a running inspection has no end; a finished one has
        CheckConstraint("(state = 'running') = (finished_at IS NULL)", name="finished_iff_not_running"),
        Index(None, "started_at"),
        Index(None, "station_id", "started_at"),
        Index(None, "part_number", "started_at"),
        Index(None, "serial"),
        Index(None, "state"),
    )


class CharacteristicResult(Base):
    """One measured characteristic, with the limits it was judged against (copied from
    the part spec at the time, so the record stays true when the spec changes)."""

    __tablename__ = "characteristic_result"

    id: Mapped[int] = mapped_column(Integer, primary_key=True, autoincrement=True)
    inspection_id: Mapped[str] = mapped_column(ForeignKey("inspection.id"))
    characteristic_id: Mapped[str] = mapped_column(String(NAME_LEN))
    unit: Mapped[str] = mapped_column(String(16))
    nominal: Mapped[float] = mapped_column(Float)
    lower_limit: Mapped[float] = mapped_column(Float)
    upper_limit: Mapped[float] = mapped_column(Float)
    #: None when the characteristic could not be measured (hole not found): a fail
    measured: Mapped[float | None] = mapped_column(Float)
    #: expanded uncertainty, coverage factor k = 2 (about 95 %), same unit
    uncertainty_k2: Mapped[float | None] = mapped_column(Float)
    passed: Mapped[bool] = mapped_column(Boolean)
    #: simulation only: the twin's true value, to score the measurement
    true_value: Mapped[float | None] = mapped_column(Float)

    inspection: Mapped[Inspection] = relationship(back_populates="characteristics")

    __table_args__ = (
        UniqueConstraint("inspection_id", "characteristic_id"),
        CheckConstraint("lower_limit < upper_limit", name="limits_ordered"),
        CheckConstraint("uncertainty_k2 IS NULL OR uncertainty_k2 >= 0", name="uncertainty_non_negative"),
        CheckConstraint("measured IS NOT NULL OR NOT passed", name="unmeasured_fails"),
    )


class ImageCrop(Base):
    """An image crop kept as evidence: a PNG under the data folder and its digest."""

    __tablename__ = "image_crop"

    id: Mapped[int] = mapped_column(Integer, primary_key=True, autoincrement=True)
    inspection_id: Mapped[str] = mapped_column(ForeignKey("inspection.id"))
    #: the characteristic or hole the crop shows (``hole_1``, ``hole_1.diameter``)
    subject: Mapped[str] = mapped_column(String(NAME_LEN))
    #: relative to the data folder, with forward slashes
    path: Mapped[str] = mapped_column(String(PATH_LEN))
    sha256: Mapped[str] = mapped_column(String(SHA256_HEX_LEN))
    created_at: Mapped[datetime] = mapped_column(UTCDateTime())

    inspection: Mapped[Inspection] = relationship(back_populates="images")

    __table_args__ = (UniqueConstraint("path"), Index(None, "inspection_id"))


#: what a scan may report beside the characteristics (docs/inspection.md, Identity)
FINDING_KINDS = ("unexpected_hole", "ambiguous_identity", "datum")


class Finding(Base):
    """Something the scan saw that the part spec does not expect (a stray drilling),
    could not resolve (two holes in one zone), or set (the part's angular datum):
    where on the part, how large, and the sentence the operator reads."""

    __tablename__ = "finding"

    id: Mapped[int] = mapped_column(Integer, primary_key=True, autoincrement=True)
    inspection_id: Mapped[str] = mapped_column(ForeignKey("inspection.id"))
    kind: Mapped[str] = mapped_column(String(32))
    message: Mapped[str] = mapped_column(Text)
    #: the spec hole it concerns, if one (``hole_1``)
    subject: Mapped[str | None] = mapped_column(String(NAME_LEN))
    #: axial position from the datum face (mm) and angle on the table (deg)
    axial_mm: Mapped[float | None] = mapped_column(Float)
    angle_deg: Mapped[float | None] = mapped_column(Float)
    diameter_mm: Mapped[float | None] = mapped_column(Float)
    #: expanded uncertainty (k = 2) of the position (mm)
    u_mm: Mapped[float | None] = mapped_column(Float)

    inspection: Mapped[Inspection] = relationship(back_populates="findings")

    __table_args__ = (CheckConstraint(_in("kind", FINDING_KINDS), name="kind"), Index(None, "inspection_id"))


class Event(Base):
    """Append-only log of state changes and alarms (the store never updates or
    deletes a row; the repository guards that in every session it opens)."""

    __tablename__ = "event"

    id: Mapped[int] = mapped_column(Integer, primary_key=True, autoincrement=True)
    #: None for station-wide events (an alarm between inspections)
    inspection_id: Mapped[str | None] = mapped_column(ForeignKey("inspection.id"))
    #: the station that logged it (None: before migration 0004)
    station_id: Mapped[str | None] = mapped_column(String(NAME_LEN))
    at: Mapped[datetime] = mapped_column(UTCDateTime())
    kind: Mapped[str] = mapped_column(String(32))
    message: Mapped[str] = mapped_column(Text)

    __table_args__ = (Index(None, "inspection_id"), Index(None, "at"), Index(None, "station_id"))


#: API token roles (docs/api.md): mes starts job orders, operator commands the
#: station, engineer changes parts, models and calibrations, admin does everything
TOKEN_ROLES = ("mes", "operator", "engineer", "admin")
#: the public part of a token, by which its row is found without trying every hash
TOKEN_PREFIX_LEN = 16


class ApiToken(Base):
    """A REST API token: only its salted hash is kept, so a copy of the database
    does not let anyone call the API. The token's public prefix finds the row."""

    __tablename__ = "api_token"

    id: Mapped[int] = mapped_column(Integer, primary_key=True, autoincrement=True)
    name: Mapped[str] = mapped_column(String(NAME_LEN))
    role: Mapped[str] = mapped_column(String(16))
    prefix: Mapped[str] = mapped_column(String(TOKEN_PREFIX_LEN))
    salt: Mapped[str] = mapped_column(String(64))  # hex
    token_hash: Mapped[str] = mapped_column(String(128))  # hex
    created_at: Mapped[datetime] = mapped_column(UTCDateTime())
    #: set when the token is revoked; a revoked token is refused, its row kept for the audit
    revoked_at: Mapped[datetime | None] = mapped_column(UTCDateTime())
    #: when the token stops working (None: never); a rotation sets it to the end of the
    #: grace, and only ever earlier than it was (migration 0005)
    expires_at: Mapped[datetime | None] = mapped_column(UTCDateTime())
    #: the token that replaced this one by a rotation (None: not rotated); a rotated
    #: token cannot be rotated again, and it always has an end
    replaced_by: Mapped[int | None] = mapped_column(ForeignKey("api_token.id"))

    __table_args__ = (
        UniqueConstraint("prefix"),
        CheckConstraint(_in("role", TOKEN_ROLES), name="role"),
        CheckConstraint("replaced_by IS NULL OR expires_at IS NOT NULL", name="replaced_token_expires"),
    )
