"""The tests' way into a data folder's database behind the store's back, on SQLite and on
PostgreSQL alike (``pytest --db``, tests/conftest.py): raw SQL, and another program
holding the write lock."""

from __future__ import annotations

import contextlib
from pathlib import Path
from typing import Iterator

from sqlalchemy import text

from station.store import engine as store_engine


def url_of(data_dir: Path) -> str:
    """The data folder's database as the store opens it by default (looked up at call
    time: under ``--db postgresql`` the folder's database is on the test cluster)."""
    return store_engine.default_url(data_dir)


def rows(data_dir: Path, sql: str, **params) -> list[tuple]:
    engine = store_engine.make_engine(url_of(data_dir))
    try:
        with engine.connect() as conn:
            return [tuple(r) for r in conn.execute(text(sql), params)]
    finally:
        engine.dispose()


@contextlib.contextmanager
def write_lock_held(data_dir: Path) -> Iterator[None]:
    """Another program holds the lock the station's writes need, until the block ends:
    SQLite, an exclusive transaction on the file (a backup tool, a sqlite3 shell);
    PostgreSQL, an exclusive lock on the inspection tables (a careless migration script)."""
    url = url_of(data_dir)
    if url.startswith("sqlite"):
        import sqlite3

        holder = sqlite3.connect(Path(url.removeprefix("sqlite:///")), timeout=1.0, isolation_level=None)
        holder.execute("BEGIN EXCLUSIVE")
        try:
            yield
        finally:
            holder.execute("ROLLBACK")
            holder.close()
        return
    engine = store_engine.make_engine(url)
    try:
        with engine.connect() as conn:
            conn.exec_driver_sql("LOCK TABLE inspection, characteristic_result, event IN ACCESS EXCLUSIVE MODE")
            try:
                yield
            finally:
                conn.rollback()
    finally:
        engine.dispose()
