"""``POST /api/v1/calibrations/master`` (issue 21, stage 3) on the simulated station: an
engineer's self-calibration runs as the station's job (409 for another job meanwhile),
is polled until done, answers the CLI's JSON object, and its proposal of the observable
parameters goes through the approval flow (picture, approval, the station's new model)."""

from __future__ import annotations

import time

import pytest

from tests.api.conftest import INSPECTION_TIMEOUT_S, start_server, stop_server


@pytest.fixture(scope="module")
def srv(tmp_path_factory):
    s, server, thread = start_server(tmp_path_factory.mktemp("calibrate-api"))
    try:
        yield s
    finally:
        stop_server(server, thread)


def test_calibration_over_rest_proposes_the_observable_parameters(srv):
    with srv.client("engineer") as eng, srv.client("operator") as op:
        assert op.post("/api/v1/calibrations/master", json={"poses": 4}).status_code == 403
        r = eng.post("/api/v1/calibrations/master", json={"artefact": "NO-SUCH-ARTEFACT"})
        assert r.status_code == 422 and "artefact" in r.json()["detail"]

        # min_significance 0: every observable parameter is proposed (6 poses on the default
        # world contradict none beyond 2 u, and the flow is what is tested here)
        r = eng.post("/api/v1/calibrations/master", json={"artefact": "CA-22.2-5x8", "poses": 6, "propose": True,
                                                          "min_significance": 0})
        assert r.status_code == 202, r.text
        run = r.json()
        assert run["state"] == "running" and run["result"] is None
        assert r.headers["location"] == f"/api/v1/calibrations/master/{run['id']}"
        # one job at a time
        assert eng.post("/api/v1/calibrations/master", json={"poses": 4}).status_code == 409
        assert op.post("/api/v1/checks", json={"kind": "master"}).status_code == 409

        deadline = time.monotonic() + INSPECTION_TIMEOUT_S
        while (run := eng.get(f"/api/v1/calibrations/master/{run['id']}").json())["state"] == "running":
            assert time.monotonic() < deadline, "calibration still running"
            time.sleep(0.3)
        assert run["state"] == "complete", run["reason"]
        doc = run["result"]
        assert set(doc) >= {"parameters", "observability", "residual_rms_um", "model_version", "poses"}
        assert doc["poses"] == 6
        assert all("truth" not in p for p in doc["parameters"])  # the twin's truth stays out of results
        seen = {p["name"] for p in doc["parameters"] if p["observable"]}
        assert seen and all(p["u"] is None for p in doc["parameters"] if not p["observable"])

        pid = doc["model_version"]
        assert pid and run["links"]["proposal"] == f"/api/v1/model-proposals/{pid}"
        p = eng.get(f"/api/v1/model-proposals/{pid}").json()
        assert p["state"] == "proposed" and p["explanation"]["kind"] == "calibration"
        assert "keep the station's current values" in p["explanation"]["description"]
        assert len(p["changes"]) == len(seen) and all(c["u"] > 0 for c in p["changes"])
        png = eng.get(p["plot_url"])
        assert png.status_code == 200 and png.content[:4] == b"\x89PNG"

        before = eng.get("/api/v1/station").json()
        r = eng.post(f"/api/v1/model-proposals/{pid}/approve", json={"note": "self-calibration"})
        assert r.status_code == 200, r.text
        assert r.json()["state"] == "approved" and r.json()["model_version"] != before.get("model_version")
        assert eng.get("/api/v1/calibrations/master/0123456789ab").status_code == 404
