"""Running the store's Alembic migrations from code.

No ``alembic.ini`` is needed at run time: the configuration is built here, with
``script_location`` pointing at the ``migrations`` folder inside this package (found
by the package's own path, so it works from a checkout, an editable install or a wheel).
"""

from __future__ import annotations

from pathlib import Path

from alembic import command
from alembic.config import Config
from alembic.runtime.migration import MigrationContext
from alembic.script import ScriptDirectory
from sqlalchemy import Connection, Engine

from station.store.engine import ADVISORY_LOCK_CLASS, MIGRATION_LOCK_KEY, WRITE_OPTION, make_engine

MIGRATIONS_DIR = Path(__file__).resolve().parent / "migrations"


def alembic_config(url: str | None = None) -> Config:
    """An Alembic config for the store (``url`` only for the alembic command line)."""
    cfg = Config()
    cfg.set_main_option("script_location", str(MIGRATIONS_DIR))
    if url is not None:
        # ConfigParser interpolation: a literal % (in a password) is written %%
        cfg.set_main_option("sqlalchemy.url", url.replace("%", "%%"))
    return cfg


def head_revision() -> str:
    return ScriptDirectory.from_config(alembic_config()).get_current_head()


def current_revision(connection: Connection) -> str | None:
    return MigrationContext.configure(connection).get_current_revision()


#: how long a station starting beside others waits for another's migration of a new
#: SQLite database (the whole migration of an empty database: seconds; two minutes
#: leaves room for a loaded PC, and a real lock-up still ends in an error)
MIGRATION_WAIT_S = 120.0


def upgrade_engine(engine: Engine) -> None:
    """Bring the engine's database to the newest revision, in one write transaction.

    Several stations may start at once on one database: the migration runs once. On
    SQLite the write lock is taken at BEGIN; on PostgreSQL a transaction-level
    advisory lock is taken before Alembic reads the current revision (and released by
    the commit). Either way the second process waits, then finds nothing to do."""
    with engine.connect().execution_options(**{WRITE_OPTION: True}) as conn:
        restore_ms = None
        if conn.dialect.name == "sqlite":
            # the stations behind the first wait for its migration, which takes seconds on
            # a loaded PC (Alembic's imports, every revision), not the few seconds an
            # ordinary write waits: set on the raw connection before the first statement
            # begins the write transaction, and put back before it returns to the pool
            raw = conn.connection.dbapi_connection
            restore_ms = raw.execute("PRAGMA busy_timeout").fetchone()[0]
            raw.execute(f"PRAGMA busy_timeout = {int(MIGRATION_WAIT_S * 1000)}")
        try:
            if conn.dialect.name == "postgresql":
                conn.exec_driver_sql(f"SELECT pg_advisory_xact_lock({ADVISORY_LOCK_CLASS}, {MIGRATION_LOCK_KEY})")
            cfg = alembic_config()
            cfg.attributes["connection"] = conn
            command.upgrade(cfg, "head")
            conn.commit()
        finally:
            if restore_ms is not None:
                conn.connection.dbapi_connection.execute(f"PRAGMA busy_timeout = {int(restore_ms)}")


def upgrade_to_head(url: str) -> None:
    """Bring the database at ``url`` to the newest revision (creates it when new)."""
    engine = make_engine(url)
    try:
        upgrade_engine(engine)
    finally:
        engine.dispose()
