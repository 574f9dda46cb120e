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
from suite_layout import REPO, is_compute_file

#: ``../shared`` beside the checkout (CI clones the project with shared/ beside it)
SHARED = REPO.parent / "shared"
BACKENDS = ("sqlite", "postgresql")


def pytest_addoption(parser):
    parser.addoption("--db", choices=BACKENDS, default=os.environ.get("STATION_TEST_DB", "sqlite"),
                     help="the results store's database for the tests: sqlite (a file per data folder) or "
                          "postgresql (a throwaway cluster, a database per data folder)")


#: the test files that take minutes (CI's --durations on a 2-core machine), slowest
#: first: under pytest-xdist (``pytest -n 2 --dist loadfile``) each worker takes whole files in collection
#: order, so these start at once and the short files fill in behind them; last, one of
#: them would run alone at the end while the other worker idles
SLOW_FILES = (
    "tests/plant/test_plant_stations.py",  # ~6-7 min: three station processes, SIGKILLs
    "tests/e2e/test_campaign.py",  # ~8-10 min in all: production campaigns in real time
    "tests/api/test_schemathesis.py",  # ~4 min: stateful sequences over the served API
    "tests/reliability/test_soak.py",  # ~3-4 min: repeated inspections, growth checks
    "tests/reliability/test_crash.py",  # ~2 min: SIGKILLs at random points
    "tests/reliability/test_fault_matrix.py",  # ~4 min over its cells
    "tests/unit/test_discovery_parts.py",
    "tests/e2e/test_scanlog.py",
    "tests/e2e/test_calibrate_master.py",
    "tests/e2e/test_calibration_observability_twins.py",
)


def _rel(item) -> str:
    path = Path(str(item.fspath)).resolve()
    try:
        return path.relative_to(REPO).as_posix()
    except ValueError:
        return path.as_posix()


def pytest_configure(config):
    config.addinivalue_line("markers", "compute: a test of computation only, nothing in real time "
                                       "(tests/suite_layout.py: is_compute_file)")


def pytest_collection_modifyitems(session, config, items):
    """Marks the tests of computation-only files ``compute`` (``-m compute`` / ``-m "not
    compute"`` split the suite as ``make test`` runs it). Under pytest-xdist (``-n N``):
    the slowest files first, in ``SLOW_FILES``' order; every other test keeps its place
    (a stable sort, so every worker collects the same order). In one stream the order
    stays as collected."""
    for item in items:
        if is_compute_file(_rel(item)):
            item.add_marker(pytest.mark.compute)
    if not (getattr(config.option, "numprocesses", None) or hasattr(config, "workerinput")):
        return
    rank = {path: i for i, path in enumerate(SLOW_FILES)}
    items.sort(key=lambda item: rank.get(_rel(item), len(SLOW_FILES)))


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
