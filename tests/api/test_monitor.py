"""The station watches itself, over REST (docs/api.md, "Station needs a check"): the
watch in the station's status and the metrics, checks on the certified master as
jobs, and the model proposals an engineer decides on.

Two served stations: the session's (a world within the station's stated U: checks in
control) and one whose calibration block was knocked 8 um along Z before the first
part (sim.drift.Collision), which only the master sees: a check there is out of
control, proposes the block's installation error, and after the engineer's approval
over REST the next check is in control again.
"""

from __future__ import annotations

import json
import re
import time
from pathlib import Path

import pytest

from tests.api.conftest import INSPECTION_TIMEOUT_S, PART, start_server, stop_server, wait_done, wait_idle

REPO = Path(__file__).resolve().parents[2]
MASTER = "MC-22.2-A"
#: the knock: the calibration block J 8 um along Z from the first second on
KNOCK = '\n[world.collision]\nat_s = 0.0\nbody = "J"\nshift = { z_um = 8.0 }\n'


def wait_check(client, check_id: str, timeout: float = INSPECTION_TIMEOUT_S) -> dict:
    """Poll a check until it has ended (as a MES would)."""
    deadline = time.monotonic() + timeout
    while True:
        r = client.get(f"/api/v1/checks/{check_id}")
        assert r.status_code == 200, r.text
        body = r.json()
        if body["state"] != "running":
            return body
        assert time.monotonic() < deadline, f"check {check_id} still running after {timeout} s"
        time.sleep(0.2)


def metric(text: str, name: str) -> float:
    m = re.search(rf"^{re.escape(name)} (\S+)$", text, re.M)
    assert m, f"{name} not in /metrics"
    return float(m.group(1))


def sse_until(lines, until: str, deadline: float) -> list[tuple[str, dict]]:
    """SSE lines parsed into (event, data), up to and including the first ``until``."""
    seen, kind, data = [], None, []
    for line in lines:
        assert time.monotonic() < deadline, f"no {until!r} event in time: {[k for k, _ in seen]}"
        if line.startswith(":"):
            continue
        if line == "":
            if kind is not None:
                seen.append((kind, json.loads("\n".join(data))))
                if kind == until:
                    return seen
            kind, data = None, []
        elif line.startswith("event:"):
            kind = line[6:].strip()
        elif line.startswith("data:"):
            data.append(line[5:].strip())
    raise AssertionError(f"the stream ended before {until!r}")


# ---------------------------------------------------------------------------- a world within U
def test_a_rest_inspection_goes_on_the_charts_and_the_station_needs_no_check(api):
    with api.client("mes") as c:
        wait_idle(c)
        before = c.get("/api/v1/station").json()
        r = c.post("/api/v1/job-orders", json={"part_number": PART, "serial": "SN-WATCH-1"})
        assert r.status_code == 202, r.text
        assert wait_done(c, r.json()["id"])["state"] == "complete"
        wait_idle(c)
        after = c.get("/api/v1/station").json()
        metrics = c.get("/metrics").text
    # the job order's inspection was put on the station's charts (observed once)
    assert after["monitor"]["inspections_observed"] == before["monitor"]["inspections_observed"] + 1
    assert after["needs_check"] is False and after["needs_check_reason"] is None
    assert after["monitor"]["needs_check"] is False and after["monitor"]["alarms"] == 0
    assert set(after["monitor"]) >= {"grating", "master", "reason"}
    assert metric(metrics, "station_needs_check") == 0
    assert metric(metrics, "station_monitor_alarms_total") == 0


def test_a_master_check_over_rest_runs_as_a_job_and_is_in_control(api):
    with api.client("operator") as op, api.client("mes") as mes:
        wait_idle(op)
        r = op.post("/api/v1/checks", json={"kind": "master"})
        assert r.status_code == 202, r.text
        started = r.json()
        assert started["state"] == "running" and started["master_id"] == MASTER and started["result"] is None
        assert r.headers["location"] == f"/api/v1/checks/{started['id']}"
        # one job at a time: a job order and a second check wait for it
        busy = mes.post("/api/v1/job-orders", json={"part_number": PART, "serial": "SN-WHILE-CHECK"})
        assert busy.status_code == 409 and "master" in busy.json()["detail"], busy.text
        assert op.post("/api/v1/checks", json={"kind": "master"}).status_code == 409
        done = wait_check(op, started["id"])
        wait_idle(op)
        status = op.get("/api/v1/station").json()
        inspection = op.get(f"/api/v1/inspections/{started['id']}").json()
    assert done["state"] == "complete" and done["in_control"] is True, done
    result = done["result"]
    assert result["in_control"] is True and result["alarms"] == [] and result["master_id"] == MASTER
    checks = {c["id"]: c for c in result["checks"]}
    assert set(checks) == {"hole_1.diameter", "hole_1.position", "hole_2.diameter", "hole_2.position"}
    for c in checks.values():
        assert abs(c["z"]) < 4.5 and c["u_station"] > 0 and c["u_certificate"] > 0
    # the twin's truth stays out, as in the job response
    assert all("true_value" not in ch for ch in result["inspection"]["characteristics"])
    assert done["proposal_id"] is None
    # the master's inspection is an inspection of the store, named by the master's id
    assert inspection["part_number"] == MASTER and inspection["state"] == "complete"
    assert status["needs_check"] is False and status["busy"] is False


@pytest.mark.parametrize("body, fragment", [
    ({"kind": "nonsense"}, "kind"),
    ({}, "kind"),
    ({"kind": "master", "master": "NO-SUCH-MASTER"}, "master"),
    ({"kind": "master", "master": "../../etc/passwd"}, "master"),
    ({"kind": "master", "master": "MC-22.2-A.toml"}, "master"),
    ({"kind": "master", "colour": "red"}, "colour"),
])
def test_a_check_of_unknown_kind_or_master_is_422_naming_the_field(api, body, fragment):
    with api.client("operator") as c:
        r = c.post("/api/v1/checks", json=body)
    assert r.status_code == 422, r.text
    assert fragment in r.text


def test_the_mes_may_not_start_a_check_and_an_unknown_check_is_404(api):
    with api.client("mes") as mes, api.client("engineer") as eng:
        r = mes.post("/api/v1/checks", json={"kind": "master"})
        assert r.status_code == 403 and "mes" in r.json()["detail"]
        assert mes.get("/api/v1/checks/no-such-check").status_code == 404
        assert eng.get("/api/v1/checks/no-such-check").status_code == 404


def test_no_proposals_and_deciding_an_unknown_one_is_404(api):
    with api.client("mes") as mes, api.client("engineer") as eng:
        listed = mes.get("/api/v1/model-proposals")
        assert listed.status_code == 200
        assert listed.json()["items"] == [] and listed.json()["model_version"].startswith("default-station")
        for pid in ("0123456789ab", "no-such-id", "..", "a" * 70):
            assert mes.get(f"/api/v1/model-proposals/{pid}").status_code == 404, pid
            assert eng.post(f"/api/v1/model-proposals/{pid}/approve").status_code == 404, pid
            assert eng.post(f"/api/v1/model-proposals/{pid}/reject", json={"note": "x"}).status_code == 404, pid
        # roles: the MES and the operator read, only an engineer (or admin) decides
        assert mes.post("/api/v1/model-proposals/0123456789ab/approve").status_code == 403
    with api.client("operator") as op:
        assert op.post("/api/v1/model-proposals/0123456789ab/reject").status_code == 403


# ---------------------------------------------------------------------------- a knocked world
@pytest.fixture(scope="module")
def knocked(tmp_path_factory):
    data = tmp_path_factory.mktemp("knocked-data")
    scenario = data / "knocked.toml"
    scenario.write_text((REPO / "sim" / "scenarios" / "default.toml").read_text() + KNOCK)
    srv, server, thread = start_server(data, scenario=scenario)
    try:
        yield srv
    finally:
        stop_server(server, thread)


def test_a_knocked_datum_is_caught_proposed_approved_over_rest_and_checked_again(knocked):
    with knocked.client("operator") as op, knocked.client("engineer") as eng, knocked.client("mes") as mes:
        wait_idle(op)
        assert op.get("/api/v1/station").json()["needs_check"] is False
        version0 = mes.get("/api/v1/model-proposals").json()["model_version"]
        with op.stream("GET", "/api/v1/events") as stream:
            lines = stream.iter_lines()
            sse_until(lines, "state", time.monotonic() + 10)  # the snapshot first
            r = op.post("/api/v1/checks", json={"kind": "master", "master": MASTER})
            assert r.status_code == 202, r.text
            seen = sse_until(lines, "check", time.monotonic() + INSPECTION_TIMEOUT_S)
        check = wait_check(op, r.json()["id"])
        wait_idle(op)
        status = mes.get("/api/v1/station").json()
        metrics = mes.get("/metrics").text
        alarms = mes.get("/api/v1/alarms").json()["items"]
        listed = mes.get("/api/v1/model-proposals").json()

        # out of control: the positions are the block's 8 um off (about 17 combined standard uncertainties)
        assert check["state"] == "complete" and check["in_control"] is False, check
        assert check["result"]["alarms"] and check["result"]["alarms"][0]["chart"] == "master"
        positions = [c for c in check["result"]["checks"] if c["id"].endswith(".position")]
        assert all(abs(c["z"]) > 4.5 for c in positions), positions
        # the MES reads "station needs a check", Prometheus too
        assert status["needs_check"] is True and status["needs_check_reason"].startswith("master check")
        assert status["monitor"]["needs_check"] is True and status["monitor"]["alarms"] == 1
        assert metric(metrics, "station_needs_check") == 1 and metric(metrics, "station_monitor_alarms_total") == 1
        assert any(a["kind"] == "alarm" and a["message"].startswith("station needs a check: master check")
                   for a in alarms), alarms
        # SSE: the job, the alarm, the proposal and the check's end
        kinds = [k for k, _ in seen]
        assert {"alarm", "proposal", "check"} <= set(kinds), kinds
        alarm = next(d for k, d in seen if k == "alarm")
        assert alarm["source"] == "check" and alarm["needs_check"] is True and alarm["inspection_id"] == check["id"]
        ended = seen[-1][1]
        assert ended["in_control"] is False and ended["proposal_id"] == check["proposal_id"]

        # the proposal: the calibration block's installation error along Z, about the knock
        (prop,) = listed["items"]
        assert prop["id"] == check["proposal_id"] and prop["state"] == "proposed"
        assert listed["model_version"] == version0 == prop["base_version"]
        (change,) = prop["changes"]
        assert change["term"] == "installation.J.z_um" and 7.0 < change["delta"] < 10.0, change
        assert set(prop["expected_change_um"]) == {"hole_1", "hole_2"}
        assert all(-10.0 < v < -7.0 for v in prop["expected_change_um"].values()), prop
        assert eng.get(f"/api/v1/model-proposals/{prop['id']}").json() == prop

        # only an engineer (or admin) decides
        assert op.post(f"/api/v1/model-proposals/{prop['id']}/approve").status_code == 403
        assert mes.post(f"/api/v1/model-proposals/{prop['id']}/approve").status_code == 403
        r = eng.post(f"/api/v1/model-proposals/{prop['id']}/approve", json={"note": "block re-seated, see log 12"})
        assert r.status_code == 200, r.text
        decided = r.json()
        assert decided["state"] == "approved" and decided["decided_by"] == "test engineer"
        assert decided["decision_note"] == "block re-seated, see log 12" and decided["decided_at"]
        assert decided["model_version"] != version0
        assert mes.get("/api/v1/model-proposals").json()["model_version"] == decided["model_version"]
        again = eng.post(f"/api/v1/model-proposals/{prop['id']}/reject")
        assert again.status_code == 409 and "already approved" in again.json()["detail"]
        approvals = knocked.runtime.store.events(kind="approval", limit=100)
        assert [e.message for e in approvals if prop["id"] in e.message and "test engineer" in e.message], \
            [e.message for e in approvals]
        assert knocked.runtime.session.model_version == decided["model_version"]

        # the next check, with the approved model: in control, and the station needs no check
        r = op.post("/api/v1/checks", json={"kind": "master"})
        assert r.status_code == 202, r.text
        check2 = wait_check(op, r.json()["id"])
        wait_idle(op)
        assert check2["in_control"] is True, check2
        assert all(abs(c["z"]) < 4.5 for c in check2["result"]["checks"]), check2["result"]["checks"]
        status = mes.get("/api/v1/station").json()
        assert status["needs_check"] is False and status["needs_check_reason"] is None
        assert metric(mes.get("/metrics").text, "station_needs_check") == 0


def test_a_rejected_proposal_leaves_the_model_as_it_was(knocked):
    """A proposal made up through the session (errors of our own making), rejected over REST."""
    from station.checks.master import load_master
    from station.monitor.proposals import datum_proposal

    session = knocked.runtime.session
    with knocked.client("engineer") as eng:
        wait_idle(eng)
        version = eng.get("/api/v1/model-proposals").json()["model_version"]
        p = datum_proposal(session.station.model, version, "made up by a test",
                           {"hole_1.position": [3.0, 3.2], "hole_2.position": [2.9]},
                           {h.id: h.position_mm for h in load_master(MASTER).holes})
        session.proposals.add(p)
        listed = eng.get("/api/v1/model-proposals").json()["items"]
        assert listed[-1]["id"] == p.id and listed[-1]["state"] == "proposed"  # newest last
        r = eng.post(f"/api/v1/model-proposals/{p.id}/reject", json={"note": "not a knock: a dirty master"})
        assert r.status_code == 200, r.text
        assert r.json()["state"] == "rejected" and r.json()["decided_by"] == "test engineer"
        assert r.json()["model_version"] == version
        assert eng.get("/api/v1/model-proposals").json()["model_version"] == version
        assert eng.post(f"/api/v1/model-proposals/{p.id}/approve").status_code == 409
    rejections = [e.message for e in knocked.runtime.store.events(kind="rejection", limit=100)]
    assert any(p.id in m and "dirty master" in m for m in rejections), rejections


def test_activating_a_model_keeps_the_approved_changes_over_it(knocked):
    """An activated model version is the station's new base: the engineer's approved
    changes are applied over it (as at every start), not lost."""
    from importlib import resources

    text = resources.files("station").joinpath("data/default_station.toml").read_text()
    with knocked.client("engineer") as eng:
        wait_idle(eng)
        before = eng.get("/api/v1/model-proposals").json()
        assert any(p["state"] == "approved" for p in before["items"]), "run after the approval above"
        up = eng.post("/api/v1/models", files={"file": ("default_station.toml", text)})
        assert up.status_code == 201, up.text
        assert eng.post(f"/api/v1/models/{up.json()['version']}/activate").status_code == 200
        after = eng.get("/api/v1/model-proposals").json()["model_version"]
    assert "+1@" in before["model_version"]
    assert after == before["model_version"]
