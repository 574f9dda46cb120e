"""Alembic environment of the results store.

Configured in code (:mod:`station.store.migrate`), never from an ``alembic.ini``: the
store hands over an open connection in ``config.attributes["connection"]`` so the
migration runs with the store's own engine settings (SQLite pragmas, the write lock
taken at BEGIN). Without one (the ``alembic`` command line, for writing a new
revision), it connects to ``sqlalchemy.url``.

The whole upgrade is one transaction (``transactional_ddl``; SQLite's DDL is
transactional once BEGIN is ours): a process killed while migrating leaves the
previous schema, never half of the next.
"""

from alembic import context

from station.store.engine import WRITE_OPTION, make_engine
from station.store.models import Base

config = context.config
target_metadata = Base.metadata


def _run(connection) -> None:
    context.configure(
        connection=connection,
        target_metadata=target_metadata,
        transactional_ddl=True,
        # SQLite cannot ALTER most things; autogenerate then writes batch operations
        render_as_batch=connection.dialect.name == "sqlite",
        compare_type=True,
    )
    with context.begin_transaction():
        context.run_migrations()


def run_migrations_online() -> None:
    connection = config.attributes.get("connection")
    if connection is not None:
        _run(connection)
        return
    engine = make_engine(config.get_main_option("sqlalchemy.url"))
    try:
        with engine.connect().execution_options(**{WRITE_OPTION: True}) as conn:
            _run(conn)
            conn.commit()
    finally:
        engine.dispose()


if context.is_offline_mode():
    raise SystemExit("the results store's migrations run online only (station.store.migrate.upgrade_to_head)")
run_migrations_online()
