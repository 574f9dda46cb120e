"""Connecting to the results database: SQLite by default, PostgreSQL by URL.

Everything SQLite-specific lives in :func:`_configure_sqlite`, so the rest of the store
speaks portable SQL through SQLAlchemy. For SQLite:

* WAL journal: readers (``station results list``, the panel) never block the
  station's writes, and a killed process leaves a database that recovers on open.
* ``synchronous=FULL``: a commit is on disk before the call returns. The store's
  promise is that a result is committed before it is reported; in WAL mode
  ``NORMAL`` could lose the last commits on a power cut.
* ``foreign_keys=ON``: SQLite does not enforce foreign keys unless asked, per connection.
* ``busy_timeout``: how long a write waits for another writer before failing with
  "database is locked" (which the store turns into a :class:`StoreError`).
* We emit ``BEGIN`` ourselves (the recipe of SQLAlchemy's SQLite dialect docs) because
  Python's sqlite3 module begins transactions late, after a SELECT; write
  transactions begin ``IMMEDIATE`` so the write lock is taken (or waited for) at the
  start, not upgraded halfway, which could fail without waiting.
"""

from __future__ import annotations

from pathlib import Path

from sqlalchemy import Engine, create_engine, event
from sqlalchemy.engine import make_url

#: the database file inside the data folder when no URL is given
DEFAULT_DB_NAME = "station.db"
#: how long a write waits for a lock held by another process (seconds); long enough
#: for a reader's snapshot or another writer's commit, short enough to alarm promptly
DEFAULT_BUSY_TIMEOUT_S = 5.0
#: execution option that marks a connection as used for writing
WRITE_OPTION = "station_store_write"


def default_url(data_dir: str | Path) -> str:
    """``sqlite:///<data_dir>/station.db`` (absolute, so a later chdir cannot move it)."""
    return f"sqlite:///{(Path(data_dir) / DEFAULT_DB_NAME).resolve()}"


def is_sqlite(url: str) -> bool:
    return make_url(url).get_backend_name() == "sqlite"


def sqlite_file(url: str) -> Path | None:
    """The database file of a SQLite URL; None for in-memory or other backends."""
    u = make_url(url)
    if u.get_backend_name() != "sqlite" or not u.database or u.database == ":memory:":
        return None
    return Path(u.database)


def make_engine(url: str, *, busy_timeout_s: float = DEFAULT_BUSY_TIMEOUT_S) -> Engine:
    """An engine for the URL; for a SQLite file its folder is created."""
    if (f := sqlite_file(url)) is not None:
        f.parent.mkdir(parents=True, exist_ok=True)
    engine = create_engine(url, future=True)
    if engine.dialect.name == "sqlite":
        _configure_sqlite(engine, busy_timeout_s)
    return engine


def _configure_sqlite(engine: Engine, busy_timeout_s: float) -> None:
    ms = int(round(busy_timeout_s * 1000))  # SQLite's busy_timeout is in milliseconds

    @event.listens_for(engine, "connect")
    def _on_connect(dbapi_conn, _record) -> None:
        dbapi_conn.isolation_level = None  # we emit BEGIN ourselves (see module doc)
        cur = dbapi_conn.cursor()
        try:
            cur.execute(f"PRAGMA busy_timeout = {ms}")
            cur.execute("PRAGMA journal_mode = WAL")
            cur.execute("PRAGMA synchronous = FULL")
            cur.execute("PRAGMA foreign_keys = ON")
        finally:
            cur.close()

    @event.listens_for(engine, "begin")
    def _on_begin(conn) -> None:
        write = conn.get_execution_options().get(WRITE_OPTION, False)
        conn.exec_driver_sql("BEGIN IMMEDIATE" if write else "BEGIN")
