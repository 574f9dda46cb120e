"""``station results qif ID``: the QIF 3.0 document of a finished inspection written
through the store, valid against the official schemas (../shared/schemas/qif3), the
same bytes as the domain exporter and the REST route; a running inspection and an
unknown id fail with a clear message and a non-zero exit status. The schemas are the
``qif_schema`` fixture of tests/conftest.py."""

from __future__ import annotations

import xml.etree.ElementTree as ET
from types import SimpleNamespace

import pytest
from typer.testing import CliRunner

from station import __version__
from station.cli import app
from station.exports.qif import QIF_NS, finished_qif_bytes
from station.parts import load_part
from station.store import FindingRecord, InspectionStateError, Measurement, Store, Traceability

PART = "ZDZG-22.2-12.3851"
NS = {"q": QIF_NS}


@pytest.fixture(scope="module")
def stored(tmp_path_factory):
    """A data folder with a failed inspection (a finding, an unmeasured hole) and one
    still running; the store is closed again, as when the CLI runs beside no station."""
    data = tmp_path_factory.mktemp("qif") / "data"
    spec = load_part(PART)
    store = Store.open(data_dir=data)
    try:
        done = store.begin_inspection(PART, serial="SN-QIF-CLI", order_id="PO-CLI", traceability=Traceability())
        m = [Measurement.of(spec.characteristic("hole_1.diameter"), 0.701, passed=True, uncertainty_k2=0.002),
             Measurement.of(spec.characteristic("hole_1.position"), 71.04, passed=True, uncertainty_k2=0.004),
             Measurement.of(spec.characteristic("hole_2.diameter"), None, passed=False),
             Measurement.of(spec.characteristic("hole_2.position"), None, passed=False)]
        findings = [FindingRecord("datum", "part's angular datum 20.000 deg on the table, set by hole_1", "hole_1",
                                  71.05, 20.0, 0.70, 0.0021)]
        store.finish(done, "complete", "fail", "hole_2 not found", measurements=m, findings=findings)
        running = store.begin_inspection(PART, serial="SN-QIF-RUN", traceability=Traceability())
        record = store.get(done)
    finally:
        store.close()
    return SimpleNamespace(data=data, done=done, running=running, record=record)


def _cli(*args: str):
    return CliRunner().invoke(app, ["results", "qif", *args])


def test_cli_writes_a_valid_document_equal_to_the_domain_exporter(stored, qif_schema):
    r = _cli(stored.done, "--data", str(stored.data))
    assert r.exit_code == 0, r.output
    doc = r.stdout_bytes
    assert doc.startswith(b"<?xml") and doc == finished_qif_bytes(stored.record, software_version=__version__)
    qif_schema.validate(doc)  # raises with the path of the first error
    root = ET.fromstring(doc)
    assert root.findtext(".//q:InspectionStatus/q:InspectionStatusEnum", namespaces=NS) == "FAIL"
    assert root.findtext(".//q:InspectionTraceability/q:ReportNumber", namespaces=NS) == stored.done
    assert root.findtext(".//q:ActualComponent/q:SerialNumber", namespaces=NS) == "SN-QIF-CLI"
    assert root.find(".//q:NotedEvents", NS).get("n") == "1"
    assert len(root.find(".//q:CharacteristicMeasurements", NS)) == 4


def test_cli_out_file_holds_the_same_bytes(stored, tmp_path):
    out = tmp_path / "done.qif"
    r = _cli(stored.done, "--out", str(out), "--data", str(stored.data))
    assert r.exit_code == 0, r.output
    assert r.stdout_bytes == b""  # the document is in the file; the note goes to stderr
    assert out.read_bytes() == finished_qif_bytes(stored.record, software_version=__version__)


def test_cli_and_rest_route_give_the_same_bytes_and_refuse_alike(stored, db_url):
    """The route on a bare app over the same store: 200 with the CLI's bytes, 409 for
    the running inspection, 404 for an unknown id."""
    import asyncio

    import httpx
    from fastapi import FastAPI

    from api import auth
    from api.routes.inspections import router

    store = Store(db_url(stored.data), data_dir=stored.data)  # read-only, as the CLI opens it

    async def get(iid: str):
        return store.get(iid)

    web = FastAPI()
    web.include_router(router)
    web.state.runtime = SimpleNamespace(records=SimpleNamespace(get=get))
    web.dependency_overrides[auth.reader] = lambda: None
    async def ask(path: str) -> httpx.Response:
        # the app in process over httpx's ASGI transport (starlette's TestClient warns
        # that its use of httpx is deprecated)
        async with httpx.AsyncClient(transport=httpx.ASGITransport(app=web), base_url="http://station",
                                     timeout=30.0) as c:
            return await c.get(path)

    try:
        q = asyncio.run(ask(f"/api/v1/inspections/{stored.done}/qif"))
        assert q.status_code == 200, q.text
        assert q.content == _cli(stored.done, "--data", str(stored.data)).stdout_bytes
        assert asyncio.run(ask(f"/api/v1/inspections/{stored.running}/qif")).status_code == 409
        assert asyncio.run(ask("/api/v1/inspections/no-such-id/qif")).status_code == 404
    finally:
        store.close()


def test_a_running_inspection_fails_clearly(stored):
    r = _cli(stored.running, "--data", str(stored.data))
    assert r.exit_code != 0 and r.stdout_bytes == b""
    assert "still running" in r.stderr and stored.running in r.stderr
    with pytest.raises(InspectionStateError):
        finished_qif_bytes(SimpleNamespace(state="running", id=stored.running))


def test_an_unknown_id_fails_clearly(stored, tmp_path):
    r = _cli("no-such-id", "--data", str(stored.data))
    assert r.exit_code != 0 and r.stdout_bytes == b""
    assert "no inspection 'no-such-id'" in r.stderr
    # a data folder without a database: no store is created, the same refusal
    empty = tmp_path / "empty"
    r = _cli("no-such-id", "--data", str(empty))
    assert r.exit_code != 0 and "no-such-id" in r.stderr
    assert not (empty / "station.db").exists()
