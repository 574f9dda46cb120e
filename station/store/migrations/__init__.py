"""Alembic migrations of the results store (run by :func:`station.store.migrate.upgrade_to_head`)."""
