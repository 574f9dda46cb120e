"""Shared test fixtures: where the shared folder (paper data, specs, schemas) lives, and
which database the store runs on.

``pytest --db postgresql`` (``make test`` runs the store, API and reliability tests a
second time so) puts every store the tests open on a throwaway PostgreSQL cluster of
their own (tests/pgcluster.py): the data folder's default database (SQLite
``<data>/station.db``) becomes a PostgreSQL database of that folder, made from a
migrated template. Everything else (the store, the API, the runtime) runs unchanged;
only the URL chosen for a data folder differs. Tests that start a child process pass
the URL on themselves (:func:`db_url`).
"""

from __future__ import annotations

import os
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
#: ``../shared`` beside the checkout (CI clones the project with shared/ beside it)
SHARED = REPO.parent / "shared"
BACKENDS = ("sqlite", "postgresql")


def pytest_addoption(parser):
    parser.addoption("--db", choices=BACKENDS, default=os.environ.get("STATION_TEST_DB", "sqlite"),
                     help="the results store's database for the tests: sqlite (a file per data folder) or "
                          "postgresql (a throwaway cluster, a database per data folder)")


def pytest_report_header(config):
    return f"results store under test: {config.getoption('--db')}"


@pytest.fixture(scope="session")
def shared_dir() -> Path:
    if not SHARED.is_dir():
        pytest.fail(f"the shared folder is missing: expected {SHARED}")
    return SHARED


@pytest.fixture(scope="session")
def paper_data(shared_dir) -> Path:
    return shared_dir / "data" / "paper"


@pytest.fixture(scope="session")
def qif_schema(shared_dir):
    """The official QIF 3.0 schemas (``shared/schemas/qif3``), loaded once per run: it
    takes seconds, and the REST tests and the CLI's tests validate against them both."""
    import xmlschema

    d = shared_dir / "schemas" / "qif3"
    return xmlschema.XMLSchema(str(d / "QIFDocument.xsd"),
                               locations={"http://www.w3.org/2000/09/xmldsig#": str(d / "xmldsig-core-schema.xsd")})


@pytest.fixture(scope="session")
def pg_cluster():
    """A PostgreSQL server of the test run's own (started on first use). Its folder is
    not under pytest's base temp: another pytest run starting meanwhile deletes the
    oldest base temps, and a server whose data folder is deleted shuts down."""
    import tempfile

    from pgcluster import PgCluster

    cluster = PgCluster(Path(tempfile.mkdtemp(prefix="station-tests-pg-"))).start()
    try:
        cluster.wait_ready()
        cluster.make_template()
        yield cluster
    finally:
        cluster.stop()


@pytest.fixture(scope="session")
def db_backend(request) -> str:
    return request.config.getoption("--db")


@pytest.fixture(scope="session", autouse=True)
def _store_backend(request, db_backend):
    """Under ``--db postgresql``: a data folder's default database is on the cluster."""
    if db_backend != "postgresql":
        yield
        return
    cluster = request.getfixturevalue("pg_cluster")
    import station.cli.results
    import station.store.engine
    import station.store.repository

    mp = pytest.MonkeyPatch()
    for module in (station.store.engine, station.store.repository, station.cli.results):
        mp.setattr(module, "default_url", cluster.database_for)
    try:
        yield
    finally:
        mp.undo()


@pytest.fixture(scope="session")
def db_url(db_backend, request):
    """``db_url(data_dir)``: the URL of a data folder's database under the run's backend
    (what the store opens by default), for tests that hand it to a child process."""
    if db_backend == "postgresql":
        return request.getfixturevalue("pg_cluster").database_for
    from station.store.engine import default_url

    return default_url


@pytest.fixture(scope="session")
def empty_db_url(db_backend, request):
    """``empty_db_url(path)``: a database with no schema at all (SQLite: a new file at
    ``path``.db; PostgreSQL: a new database on the cluster), to test migrations."""
    if db_backend == "postgresql":
        cluster = request.getfixturevalue("pg_cluster")
        return lambda path: cluster.database_for(path, empty=True)
    return lambda path: f"sqlite:///{Path(path).with_suffix('.db')}"
