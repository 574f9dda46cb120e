"""The pictures over REST (issue 20, "show it"): a model proposal's before/after PNG
(``GET /model-proposals/{id}/plot``, ``plot_url`` in its JSON) and a discovery run's
residual plots (``GET /reports/discovery/{id}/plots/{name}``, ``plots`` in its stored
report).

A server of its own (a temporary data folder): the proposals made here would be seen
by the session server's other tests, which expect none.
"""

from __future__ import annotations

import http.client
import io
import json
import struct
import uuid
from datetime import datetime, timezone
from urllib.parse import quote, urlsplit

import httpx
import numpy as np
import pytest

from api.sessions import SESSION_COOKIE
from tests.api.conftest import ROLES, start_server, stop_server

PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
SENTINEL = "PLOTS-SENTINEL-7f3a"


@pytest.fixture(scope="module")
def srv(tmp_path_factory):
    base = tmp_path_factory.mktemp("plots")
    data = base / "data"
    data.mkdir()
    (base / "sentinel.png").write_text(SENTINEL)  # beside the data folder: never to be served
    (base / "sentinel.txt").write_text(SENTINEL)
    server, uv, thread = start_server(data)
    try:
        yield server
    finally:
        stop_server(uv, thread)


def png_image(data: bytes) -> np.ndarray:
    """The PNG's pixels (rows x columns x channels, 0..1), after checking it is a whole
    PNG: the signature, IHDR first, IEND last."""
    assert data[:8] == PNG_SIGNATURE, data[:16]
    length, kind = struct.unpack(">I4s", data[8:16])
    assert kind == b"IHDR" and length == 13
    width, height = struct.unpack(">II", data[16:24])
    assert data[-12:] == b"\x00\x00\x00\x00IEND\xaeB`\x82", data[-12:]
    from PIL import Image

    with Image.open(io.BytesIO(data)) as im:
        im.load()
        assert im.format == "PNG" and im.size == (width, height)
        return np.asarray(im.convert("RGB"), dtype=float) / 255.0


def assert_drawn(data: bytes, min_width: int = 500, min_height: int = 250) -> np.ndarray:
    """A picture matplotlib drew: of a figure's size, with axes, lines and text on it
    (not a blank or a one-colour image)."""
    px = png_image(data)
    h, w, _ = px.shape
    assert w >= min_width and h >= min_height, (w, h)
    ink = np.any(px < 0.9, axis=2).mean()  # share of pixels that are not (near) white
    assert 0.01 < ink < 0.6, ink
    colours = {tuple(c) for c in (px[::3, ::3] * 255).astype(int).reshape(-1, 3)}
    assert len(colours) > 50, len(colours)  # anti-aliased text and lines, in colour
    chroma = px.max(axis=2) - px.min(axis=2)
    assert (chroma > 0.3).mean() > 1e-4  # coloured series, not only black on white
    return px


def raw_get(srv, target: str, headers: dict[str, str]) -> tuple[int, dict, bytes]:
    """A GET with the target exactly as given (httpx would normalise ``..``)."""
    port = urlsplit(srv.url).port
    conn = http.client.HTTPConnection("127.0.0.1", port, timeout=30)
    try:
        conn.putrequest("GET", target, skip_accept_encoding=True)
        for k, v in headers.items():
            conn.putheader(k, v)
        conn.endheaders()
        r = conn.getresponse()
        return r.status, {k.lower(): v for k, v in r.getheaders()}, r.read()
    finally:
        conn.close()


def bearer(srv, role: str = "mes") -> dict[str, str]:
    return {"Authorization": f"Bearer {srv.tokens[role]}"}


# ---------------------------------------------------------------------------- model proposals
def make_proposal(srv, points: bool):
    """A proposal as the station makes one after a knock (a step of about +8 um at two
    holes), with the checks it rests on (``points``) or without."""
    from station.monitor.proposals import Change, Proposal

    pts = []
    if points:
        rng = np.random.default_rng(4)
        for k in range(6):
            for hole in ("hole_1", "hole_2"):
                step = 8.0 if k >= 3 else 0.0
                pts.append({"time_s": 600.0 * k, "hole": hole, "error_um": step + float(rng.normal(0, 0.4)),
                            "u_um": 0.6})
    p = Proposal(uuid.uuid4().hex[:12], datetime.now(timezone.utc).isoformat(), "default-station@test",
                 "master check out of control (a test)", [Change("installation.J.z_um", 8.1, why="a test")],
                 {"hole_1.position": [8.2], "hole_2.position": [7.9]}, {"hole_1": -8.0, "hole_2": -8.1},
                 explanation={"kind": "step", "description": "the errors jumped by +8.0 um between two checks",
                              "points": pts} if points else {})
    return srv.runtime.session.proposals.add(p)


@pytest.fixture(scope="module")
def pictured(srv):
    return make_proposal(srv, points=True)


@pytest.fixture(scope="module")
def unpictured(srv):
    return make_proposal(srv, points=False)


def test_a_proposal_with_checks_to_show_serves_its_picture(srv, pictured):
    url = f"/api/v1/model-proposals/{pictured.id}/plot"
    with httpx.Client(base_url=srv.url, headers=bearer(srv, "mes"), timeout=30) as c:
        listed = {p["id"]: p for p in c.get("/api/v1/model-proposals").json()["items"]}
        assert listed[pictured.id]["plot_url"] == url
        assert c.get(f"/api/v1/model-proposals/{pictured.id}").json()["plot_url"] == url
        r = c.get(url)
    assert r.status_code == 200, r.text
    assert r.headers["content-type"] == "image/png"
    assert r.headers["x-content-type-options"] == "nosniff"
    assert r.content == srv.runtime.session.proposals.plot_path(pictured.id).read_bytes()
    px = assert_drawn(r.content, min_width=900, min_height=300)  # two panels side by side (11 x 4 in)
    # before and after are drawn apart: the left half and the right half differ
    half = px.shape[1] // 2
    assert np.abs(px[:, :half] - px[:, half:2 * half]).mean() > 0.005


def test_a_proposal_without_a_picture_says_so(srv, unpictured):
    with httpx.Client(base_url=srv.url, headers=bearer(srv, "engineer"), timeout=30) as c:
        listed = {p["id"]: p for p in c.get("/api/v1/model-proposals").json()["items"]}
        assert listed[unpictured.id]["plot_url"] is None
        assert c.get(f"/api/v1/model-proposals/{unpictured.id}").json()["plot_url"] is None
        r = c.get(f"/api/v1/model-proposals/{unpictured.id}/plot")
    assert r.status_code == 404
    assert r.headers["content-type"] == "application/json"
    assert "has no picture" in r.json()["detail"] and unpictured.id in r.json()["detail"]


def test_an_unknown_proposal_has_no_picture(srv):
    with httpx.Client(base_url=srv.url, headers=bearer(srv), timeout=30) as c:
        r = c.get("/api/v1/model-proposals/0123456789ab/plot")
    assert r.status_code == 404 and r.headers["content-type"] == "application/json"
    assert r.json()["detail"] == "no proposal '0123456789ab'"


def test_a_decision_answers_with_the_plot_url(srv):
    p = make_proposal(srv, points=True)
    with httpx.Client(base_url=srv.url, headers=bearer(srv, "engineer"), timeout=30) as c:
        r = c.post(f"/api/v1/model-proposals/{p.id}/reject", json={"note": "a test"})
        assert r.status_code == 200, r.text
        assert r.json()["state"] == "rejected"
        assert r.json()["plot_url"] == f"/api/v1/model-proposals/{p.id}/plot"
        assert c.get(r.json()["plot_url"]).status_code == 200  # a decided proposal keeps its picture


def test_who_may_see_a_proposals_picture(srv, pictured):
    """As the access matrix says: any valid credential reads it (a token of any role,
    or the panel's session cookie, which needs no CSRF header on a read: an <img>
    sends none); no credential or a bad one is 401."""
    url = f"/api/v1/model-proposals/{pictured.id}/plot"
    with httpx.Client(base_url=srv.url, timeout=30) as c:
        for role in ROLES:
            r = c.get(url, headers=bearer(srv, role))
            assert r.status_code == 200 and r.content[:8] == PNG_SIGNATURE, role
        for headers in ({}, {"Authorization": "Bearer nonsense"}, {"Cookie": f"{SESSION_COOKIE}={'y' * 43}"}):
            r = c.get(url, headers=headers)
            assert r.status_code == 401 and PNG_SIGNATURE not in r.content, headers
        login = c.post("/api/v1/session", json={"token": srv.tokens["operator"]})
        assert login.status_code == 200
        r = c.get(url)  # the cookie from the login, nothing else
        assert r.status_code == 200 and r.content[:8] == PNG_SIGNATURE


def test_a_proposals_picture_is_named_by_its_id_only(srv, pictured):
    base = srv.data_dir.parent
    for pid in ["..", "%2e%2e", "..%2F..%2Fsentinel", "..%2f..%2fsentinel.png", "%2e%2e%2f%2e%2e%2fsentinel",
                quote(str(base / "sentinel"), safe=""), quote(str(base / "sentinel.png"), safe=""),
                "sentinel", f"{pictured.id}%00", f"{pictured.id}.png", f"{pictured.id}%2Fplot", "a" * 70,
                f"..%2Fproposals%2F{pictured.id}"]:
        status, headers, body = raw_get(srv, f"/api/v1/model-proposals/{pid}/plot", bearer(srv))
        assert 400 <= status < 500, (pid, status, body[:200])
        assert SENTINEL.encode() not in body and PNG_SIGNATURE not in body, pid
    for target in [f"/api/v1/model-proposals/{pictured.id}/../../../sentinel.png",
                   f"/api/v1/model-proposals/{pictured.id}/plot/..%2F..%2F..%2Fsentinel.png"]:
        status, _h, body = raw_get(srv, target, bearer(srv))
        assert 400 <= status < 500 and SENTINEL.encode() not in body, (target, status)


# ---------------------------------------------------------------------------- discovery runs
MODEL_TOML = ('[axis]\nname = "Z"\nkind = "linear"\n\n[baseline]\ntarget = [0.0, 60.0, 120.0]\n'
              'deviation = [0.0, 9.0, 18.0]\n\n[noise]\nsigma = 0.5\n')


@pytest.fixture(scope="module")
def discovered(srv) -> dict:
    """A discovery run over REST (a recording with 4 um of backlash the model lacks):
    its stored entry as GET answers it."""
    from station.discovery.synth import Campaign, linear_model, make_recording
    from station.effects import Backlash

    rec = make_recording(linear_model(), (Backlash(4.0),), Campaign(seed=5))
    with httpx.Client(base_url=srv.url, headers=bearer(srv, "engineer"), timeout=120) as c:
        r = c.post("/api/v1/reports/discovery", files={"model": ("m.toml", MODEL_TOML),
                                                        "recording": ("r.csv", rec.to_csv())})
        assert r.status_code == 200, r.text
        entry = c.get(r.headers["location"]).json()
    assert entry["report"] == r.json()  # the POST's answer is the report, as `station discover` writes it
    return entry


def test_a_discovery_run_keeps_and_serves_its_residual_plots(srv, discovered):
    plots = {p["name"]: p for p in discovered["plots"]}
    # the residual before and after against position, time and direction (docs: discovery.md section 3)
    assert {"residual_position.png", "residual_time.png", "residual_direction.png"} <= set(plots), plots
    folder = srv.data_dir / "reports" / "discovery" / discovered["id"]
    assert {f.name for f in folder.iterdir()} == set(plots)
    with httpx.Client(base_url=srv.url, headers=bearer(srv, "mes"), timeout=30) as c:
        for name, p in plots.items():
            assert p["url"] == f"/api/v1/reports/discovery/{discovered['id']}/plots/{name}"
            assert p["view"]
            r = c.get(p["url"])
            assert r.status_code == 200, (name, r.text)
            assert r.headers["content-type"] == "image/png"
            assert r.content == (folder / name).read_bytes()
            assert_drawn(r.content, min_width=700)
        # the position plot: residual before (backlash: two bands) and after (one) side by side, unlike
        px = png_image(c.get(plots["residual_position.png"]["url"]).content)
    half = px.shape[1] // 2
    assert np.abs(px[:, :half] - px[:, half:2 * half]).mean() > 0.005


def test_only_the_plots_a_run_wrote_are_served(srv, discovered):
    rid = discovered["id"]
    folder = srv.data_dir / "reports" / "discovery"
    served = [p["name"] for p in discovered["plots"]]
    with httpx.Client(base_url=srv.url, headers=bearer(srv), timeout=30) as c:
        # not a plot's name at all: 422 (the name's pattern), files the run wrote that are no plot: never
        for name in ("report.json", f"{rid}.json", "model.toml", "x.PNG", ".png", "a b.png"):
            r = c.get(f"/api/v1/reports/discovery/{rid}/plots/{quote(name)}")
            assert r.status_code in (404, 422), (name, r.status_code)
            assert PNG_SIGNATURE not in r.content
        # a plot's name of the right form that the run did not list: 404, even with a file of that name there
        (folder / rid / "stray.png").write_bytes((folder / rid / served[0]).read_bytes())
        r = c.get(f"/api/v1/reports/discovery/{rid}/plots/stray.png")
        assert r.status_code == 404 and "has no plot 'stray.png'" in r.json()["detail"]
        (folder / rid / "stray.png").unlink()
        # an unknown report, and a report stored before reports kept plots
        other = str(uuid.uuid4())
        r = c.get(f"/api/v1/reports/discovery/{other}/plots/residual_position.png")
        assert r.status_code == 404 and r.json()["detail"] == f"no discovery report {other}"
        old = {k: v for k, v in json.loads((folder / f"{rid}.json").read_text()).items() if k != "plots"}
        old["id"] = other
        (folder / f"{other}.json").write_text(json.dumps(old))
        try:
            assert c.get(f"/api/v1/reports/discovery/{other}").json()["plots"] == []
            r = c.get(f"/api/v1/reports/discovery/{other}/plots/residual_position.png")
            assert r.status_code == 404, r.text
        finally:
            (folder / f"{other}.json").unlink()
        assert c.get("/api/v1/reports/discovery/not-a-uuid/plots/residual_position.png").status_code == 422


def test_a_discovery_plot_cannot_name_another_file(srv, discovered):
    rid = discovered["id"]
    base = srv.data_dir.parent
    names = ["..", "%2e%2e", "..%2F..%2F..%2F..%2Fsentinel.png", "..%2f..%2f..%2f..%2fsentinel.png",
             "%2e%2e%2f%2e%2e%2f%2e%2e%2f%2e%2e%2fsentinel.png", "..%252F..%252Fsentinel.png", "..%5C..%5Csentinel.png",
             quote(str(base / "sentinel.png"), safe=""), "%2F" + quote(str(base / "sentinel.png"), safe=""),
             f"..%2F{rid}.json", "sentinel.png", "sentinel.png%00", "residual_position.png%00.txt",
             "..%2F..%2F..%2F..%2Fsentinel.txt"]
    ids = ["..", "%2e%2e", f"..%2F{rid}", quote(str(base), safe=""), f"{rid}%2F..%2F..%2F..%2F.."]
    targets = [f"/api/v1/reports/discovery/{rid}/plots/{n}" for n in names]
    targets += [f"/api/v1/reports/discovery/{i}/plots/sentinel.png" for i in ids]
    targets += [f"/api/v1/reports/discovery/{rid}/plots/../../../../../sentinel.png",
                f"/api/v1/reports/discovery/{rid}/../../../../sentinel.png"]
    for target in targets:
        status, _h, body = raw_get(srv, target, bearer(srv))
        assert 400 <= status < 500, (target, status, body[:200])
        assert SENTINEL.encode() not in body and PNG_SIGNATURE not in body, target
