"""Live data: SSE during an inspection, MJPEG frames, Prometheus metrics, station
state and axes, commands."""

from __future__ import annotations

import json
import re
import time

import cv2
import numpy as np

from tests.api.conftest import PART, wait_done, wait_idle


def _sse_events(lines, until: str, deadline: float):
    """Parse SSE lines into (event, data) until an event named ``until``."""
    kind, data = None, []
    for line in lines:
        if time.monotonic() > deadline:
            raise AssertionError("no '%s' event in time" % until)
        if line.startswith(":"):
            continue
        if line == "":
            if kind is not None:
                yield kind, json.loads("\n".join(data))
                if kind == until:
                    return
            kind, data = None, []
        elif line.startswith("event:"):
            kind = line[6:].strip()
        elif line.startswith("data:"):
            data.append(line[5:].strip())


def test_sse_delivers_state_progress_and_the_result(api):
    with api.client("operator") as c, api.client("mes") as mes:
        wait_idle(c)
        with c.stream("GET", "/api/v1/events") as stream:
            assert stream.status_code == 200
            assert stream.headers["content-type"].startswith("text/event-stream")
            lines = stream.iter_lines()
            first_kind, first = next(_sse_events(lines, "state", time.monotonic() + 10))
            assert first_kind == "state" and "state" in first and "busy" in first
            r = mes.post("/api/v1/job-orders", json={"part_number": PART, "serial": "SN-SSE"})
            assert r.status_code == 202
            seen = list(_sse_events(lines, "result", time.monotonic() + 120))
    kinds = [k for k, _ in seen]
    states = [d["state"] for k, d in seen if k == "state"]
    assert "running" in states
    progress = [d for k, d in seen if k == "progress"]
    assert progress and all(0 < p["done"] <= p["total"] for p in progress)
    assert progress[-1]["done"] == progress[-1]["total"]
    started = [d for k, d in seen if k == "job" and d["event"] == "started"]
    assert started and started[0]["inspection_id"] == r.json()["id"]
    result = seen[-1][1]
    assert kinds[-1] == "result" and result["id"] == r.json()["id"] and result["result"] == "pass"
    # the inspection's documents, live: every measurement frame, each hole, each characteristic
    iid = r.json()["id"]
    frames = [d for k, d in seen if k == "frame"]
    holes = [d for k, d in seen if k == "hole"]
    chars = [d for k, d in seen if k == "characteristic"]
    assert frames and all(d["inspection_id"] == iid for d in frames + holes + chars), sorted(set(kinds))
    assert sorted(h["hole"] for h in holes) == ["hole_1", "hole_2"] and all(h["found"] for h in holes)
    assert sum(h["frames"] for h in holes) == len(frames)
    assert kinds.index("frame") < kinds.index("hole") < kinds.index("characteristic") < kinds.index("result")
    assert {c["id"]: c["measured"] for c in chars} == {c["id"]: c["measured"] for c in result["characteristics"]}


def test_mjpeg_delivers_jpeg_frames(api):
    with api.client("operator") as c:
        with c.stream("GET", "/api/v1/camera.mjpg") as r:
            assert r.status_code == 200
            ctype = r.headers["content-type"]
            assert ctype.startswith("multipart/x-mixed-replace")
            boundary = re.search(r"boundary=(\S+)", ctype).group(1).encode()
            buf = b""
            deadline = time.monotonic() + 30
            for chunk in r.iter_bytes():
                buf += chunk
                if buf.count(b"--" + boundary) >= 3 or time.monotonic() > deadline:
                    break
    parts = [p for p in buf.split(b"--" + boundary) if b"image/jpeg" in p]
    assert len(parts) >= 2
    for part in parts[:2]:
        head, _, body = part.partition(b"\r\n\r\n")
        length = int(re.search(rb"Content-Length: (\d+)", head).group(1))
        image = cv2.imdecode(np.frombuffer(body[:length], np.uint8), cv2.IMREAD_GRAYSCALE)
        assert image is not None and image.size > 0


def _metric(text: str, name: str, labels: str = "") -> float:
    m = re.search(rf"^{re.escape(name)}{re.escape(labels)} (\S+)$", text, re.M)
    assert m, f"{name}{labels} not in /metrics"
    return float(m.group(1))


def test_metrics_count_inspections(api):
    with api.client("mes") as c:
        wait_idle(c)
        before = c.get("/metrics").text
        r = c.post("/api/v1/job-orders", json={"part_number": PART, "serial": "SN-METRICS"})
        wait_done(c, r.json()["id"])
        wait_idle(c)
        after = c.get("/metrics")
    assert after.status_code == 200 and after.headers["content-type"].startswith("text/plain")
    text = after.text
    assert _metric(text, "station_inspections_total", '{result="pass"}') == \
        _metric(before, "station_inspections_total", '{result="pass"}') + 1
    assert _metric(text, "station_inspection_duration_seconds_count") == \
        _metric(before, "station_inspection_duration_seconds_count") + 1
    assert 0 < _metric(text, "station_pass_rate") <= 1
    assert _metric(text, "station_driver_errors_total", '{kind="fault"}') >= 0
    assert _metric(text, "station_busy") == 0


def test_station_axes_and_commands(api):
    with api.client("operator") as c:
        wait_idle(c)
        st = c.get("/api/v1/station").json()
        assert st["mode"] == "simulated" and st["busy"] is False
        axes = c.get("/api/v1/axes").json()
        assert axes["Z"]["error"] is None and axes["Z"]["unit"] == "mm"
        assert axes["C"]["error"] is None and axes["C"]["unit"] == "deg"
        assert axes["grating"]["error"] is None and isinstance(axes["grating"]["position"], float)
        # nothing runs: pause is refused with the reason
        r = c.post("/api/v1/station/pause")
        assert r.status_code == 409 and "nothing is running" in r.json()["detail"]
        assert c.post("/api/v1/station/jump").status_code == 422
        r = c.post("/api/v1/station/home")
        assert r.status_code == 200, r.text
        wait_idle(c)
        assert c.get("/api/v1/station").json()["state"] == "ready"
        assert c.get("/healthz").json() == {"status": "ok"}
        ready = c.get("/readyz")
        assert ready.status_code == 200 and ready.json()["ready"] is True


def test_pause_resume_and_abort_over_rest(api):
    with api.client("operator") as op, api.client("mes") as mes:
        wait_idle(op)
        r = mes.post("/api/v1/job-orders", json={"part_number": PART, "serial": "SN-ABORT"})
        assert r.status_code == 202
        deadline = time.monotonic() + 60
        while op.get("/api/v1/station").json()["state"] != "running":
            assert time.monotonic() < deadline
            time.sleep(0.05)
        assert op.post("/api/v1/station/pause").status_code == 200
        while op.get("/api/v1/station").json()["state"] != "paused":
            assert time.monotonic() < deadline, "never paused"
            time.sleep(0.05)
        assert op.post("/api/v1/station/abort").status_code == 200
        done = wait_done(op, r.json()["id"])
    assert done["state"] == "aborted" and "test operator" in done["reason"]
