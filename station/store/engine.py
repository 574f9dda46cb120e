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

import random
import sqlite3
import time
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
#: PostgreSQL advisory-lock class of the store's locks (an arbitrary 32-bit number,
#: "STOR"); the second key names what is locked: the schema's migration, or a station
ADVISORY_LOCK_CLASS = 0x53544F52
MIGRATION_LOCK_KEY = 0


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
    kw = {}
    if make_url(url).get_backend_name() == "postgresql":
        kw = postgresql_options(busy_timeout_s)
    engine = create_engine(url, future=True, **kw)
    if engine.dialect.name == "sqlite":
        _configure_sqlite(engine, busy_timeout_s)
    return engine


#: PostgreSQL: longest wait for the server to accept a connection (s)
PG_CONNECT_TIMEOUT_S = 10
#: PostgreSQL: longest any one statement may run (ms); the store's statements are
#: small (one inspection, one page of a list), so a minute means something is wrong
PG_STATEMENT_TIMEOUT_MS = 60_000


def postgresql_options(busy_timeout_s: float) -> dict:
    """Engine options for PostgreSQL (psycopg 3), the counterparts of the SQLite pragmas:

    * ``synchronous_commit=on`` per connection, whatever the server's default: a commit
      is on the server's disk (and a synchronous standby's, if any) before it returns,
      which is the store's "committed before reported".
    * ``lock_timeout`` = the busy timeout: a write waiting for a row or table lock
      fails after that long (a :class:`StoreUnavailable` naming the lock), as SQLite's
      ``busy_timeout``; ``statement_timeout`` bounds everything else.
    * ``connect_timeout`` and TCP keepalives: a server that is gone, or a network that
      dropped the connection, is found in seconds, not after the kernel's two hours.
    * ``pool_pre_ping``: a connection the server closed (a restart, a failover) is
      replaced before use instead of failing the station's next write.
    """
    lock_ms = max(1, int(round(busy_timeout_s * 1000)))
    options = (f"-c synchronous_commit=on -c lock_timeout={lock_ms} "
               f"-c statement_timeout={PG_STATEMENT_TIMEOUT_MS} -c idle_in_transaction_session_timeout=300000")
    return {
        "pool_pre_ping": True,
        "connect_args": {"connect_timeout": PG_CONNECT_TIMEOUT_S, "options": options, "keepalives": 1,
                         "keepalives_idle": 30, "keepalives_interval": 10, "keepalives_count": 3,
                         "application_name": "bore-station"},
    }


def _set_wal(cur, wait_s: float) -> None:
    """Put the database in WAL mode, waiting up to ``wait_s`` for other processes.

    A new database is turned to WAL by the first connection that asks. When several
    processes open a new file at the same moment (stations starting together), each
    holds a shared lock while it asks for the exclusive one; SQLite sees the deadlock
    and answers "database is locked" at once, without calling the busy handler (seen
    in 1 of 30-60 starts of six processes on a 2-core PC). Backing off and asking again
    lets the one that won finish; only a lock held past ``wait_s`` is an error."""
    deadline = time.monotonic() + wait_s
    delay = 0.005
    while True:
        try:
            cur.execute("PRAGMA journal_mode = WAL")
            return
        except sqlite3.OperationalError as exc:
            low = str(exc).lower()
            if ("locked" not in low and "busy" not in low) or time.monotonic() + delay > deadline:
                raise
        time.sleep(delay * (0.5 + random.random()))  # jittered, so the losers do not collide again
        delay = min(2 * delay, 0.25)


def _configure_sqlite(engine: Engine, busy_timeout_s: float) -> None:
    ms = int(round(busy_timeout_s * 1000))  # SQLite's busy_timeout is in milliseconds

    @event.listens_for(engine, "connect")
    def _on_connect(dbapi_conn, _record) -> None:
        dbapi_conn.isolation_level = None  # we emit BEGIN ourselves (see module doc)
        cur = dbapi_conn.cursor()
        try:
            cur.execute(f"PRAGMA busy_timeout = {ms}")
            _set_wal(cur, busy_timeout_s)
            cur.execute("PRAGMA synchronous = FULL")
            cur.execute("PRAGMA foreign_keys = ON")
        finally:
            cur.close()

    @event.listens_for(engine, "begin")
    def _on_begin(conn) -> None:
        write = conn.get_execution_options().get(WRITE_OPTION, False)
        conn.exec_driver_sql("BEGIN IMMEDIATE" if write else "BEGIN")
