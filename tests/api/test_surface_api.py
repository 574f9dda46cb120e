"""The whole-surface inspection over REST (issue 23): ``surface`` in the job response
(``GET /inspections/{id}``: the picture's meta with its URL, the defects without the
twin's truth, frames, coverage, notes; null without one) and the unrolled picture
(``GET /inspections/{id}/surface.png``: the PNG the store kept, its SHA-256 as ETag;
404 with a clear detail without one; readers only, as the other pictures).

A server of its own (a temporary data folder); the records are written through the
station's own store as the StoreWriter writes them (tests/surface_cases.py). Under
``make test``'s PostgreSQL run this is also the store's round trip of the surface on
PostgreSQL (JSONB document, picture row in the same commit)."""

from __future__ import annotations

import hashlib

import cv2
import httpx
import numpy as np
import pytest

from api.sessions import SESSION_COOKIE
from surface_cases import DEFECTS, NO_SURFACE_SPEC, store_surface_record, synthetic_surface
from tests.api.conftest import ROLES, start_server, stop_server

PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"


@pytest.fixture(scope="module")
def srv(tmp_path_factory):
    server, uv, thread = start_server(tmp_path_factory.mktemp("surface-api") / "data")
    try:
        yield server
    finally:
        stop_server(uv, thread)


@pytest.fixture(scope="module")
def records(srv):
    """Four inspections: with a surface and its picture, with a surface but no picture,
    without surface inspection, and with a surface stored before it held the camera's
    blur (session 62)."""
    store = srv.runtime.store
    surface = synthetic_surface()
    return {
        "full": (store_surface_record(store, "SN-SURF", surface), surface),
        "no_picture": (store_surface_record(store, "SN-SURF-NOPIC", synthetic_surface(with_picture=False)), None),
        "none": (store_surface_record(store, "SN-PLAIN", None, result="pass"), None),
        "older": (_older_record(store), None),
    }


def _older_record(store) -> str:
    """A record whose surface document has no ``blur_px`` (written before session 62)."""
    from station.parts import load_part
    from station.store import Measurement

    c = load_part("ZDZG-22.2-12.3851").characteristic("hole_1.diameter")
    doc = synthetic_surface(with_picture=False).to_json(with_truth=True)
    del doc["blur_px"]
    iid = store.begin_inspection("ZDZG-22.2-12.3851", serial="SN-SURF-OLD")
    store.finish(iid, "complete", "fail", "surface defects reject the part",
                 measurements=[Measurement.of(c, c.nominal, passed=True, uncertainty_k2=0.004)], surface=doc)
    return iid


def test_the_job_response_carries_the_surface(srv, records):
    iid, surface = records["full"]
    with srv.client("mes") as c:
        r = c.get(f"/api/v1/inspections/{iid}")
    assert r.status_code == 200, r.text
    body = r.json()
    s = body["surface"]
    assert set(s) == {"picture", "defects", "frames", "recentred", "axial_from_mm", "axial_to_mm", "coverage", "notes",
                      "blur_px"}
    assert (s["frames"], s["recentred"], s["coverage"], s["blur_px"]) == (48, 3, 0.996, 1.21)
    assert (s["axial_from_mm"], s["axial_to_mm"]) == (60.0, 100.0)
    assert s["notes"] == surface.notes
    # the picture: where its pixels are on the part, and where to get it
    meta = surface.picture.meta()
    assert s["picture"]["url"] == f"/api/v1/inspections/{iid}/surface.png"
    assert {k: v for k, v in s["picture"].items() if k != "url"} == pytest.approx(meta, rel=1e-12)
    assert (s["picture"]["width_px"], s["picture"]["height_px"]) == surface.picture.image.shape[::-1]
    # every defect as measured, the twin's truth left out (as a characteristic's true_value is)
    assert [d["id"] for d in s["defects"]] == [d[0] for d in DEFECTS]
    for d, want in zip(s["defects"], surface.defects):
        assert "truth" not in d
        assert d == {k: v for k, v in want.to_json().items()}
    rejects = {d["id"]: d["rejects"] for d in s["defects"] if d["rejects"]}
    assert set(rejects) == {"d1", "d4"}
    assert s["defects"][3]["hole"] == "hole_1" and s["defects"][0]["zone"] == "seal_1"
    # the picture's image digest is among the record's images
    (img,) = [i for i in body["images"] if i["subject"] == "surface"]
    assert len(img["sha256"]) == 64


def test_the_picture_is_served_as_stored(srv, records):
    iid, surface = records["full"]
    with srv.client("operator") as c:
        r = c.get(f"/api/v1/inspections/{iid}/surface.png")
        assert r.status_code == 200, r.text
        assert r.headers["content-type"] == "image/png" and r.content.startswith(PNG_SIGNATURE)
        assert r.headers["cache-control"] == "private, no-cache"
        digest = hashlib.sha256(r.content).hexdigest()
        (img,) = [i for i in c.get(f"/api/v1/inspections/{iid}").json()["images"] if i["subject"] == "surface"]
        assert digest == img["sha256"] and r.headers["etag"] == f'"{digest}"'
        decoded = cv2.imdecode(np.frombuffer(r.content, np.uint8), cv2.IMREAD_UNCHANGED)
        np.testing.assert_array_equal(decoded, surface.picture.image)
        # revalidation: the same picture is not sent again
        again = c.get(f"/api/v1/inspections/{iid}/surface.png", headers={"If-None-Match": r.headers["etag"]})
        assert again.status_code == 304 and again.content == b"" and again.headers["etag"] == r.headers["etag"]
        other = c.get(f"/api/v1/inspections/{iid}/surface.png", headers={"If-None-Match": '"0000"'})
        assert other.status_code == 200 and other.content == r.content


def test_without_a_picture_404_says_why(srv, records):
    none, _ = records["none"]
    nopic, _ = records["no_picture"]
    with srv.client("engineer") as c:
        body = c.get(f"/api/v1/inspections/{none}").json()
        assert body["surface"] is None and body["images"] == []
        r = c.get(f"/api/v1/inspections/{none}/surface.png")
        assert r.status_code == 404 and r.headers["content-type"] == "application/json"
        assert r.json()["detail"] == (f"inspection {none} has no surface picture (its part spec asks for no "
                                      "surface inspection, or it did not complete)")
        body = c.get(f"/api/v1/inspections/{nopic}").json()
        assert body["surface"]["picture"] is None and len(body["surface"]["defects"]) == len(DEFECTS)
        r = c.get(f"/api/v1/inspections/{nopic}/surface.png")
        assert r.status_code == 404 and "made no picture" in r.json()["detail"]
        r = c.get("/api/v1/inspections/00000000-0000-4000-8000-000000000000/surface.png")
        assert r.status_code == 404 and r.json()["detail"].startswith("no inspection")


def test_a_surface_stored_before_the_camera_blur_still_reads(srv, records):
    """A record written before the surface held ``blur_px`` (session 62) is served as
    stored, without it, everything else as before."""
    older, _ = records["older"]
    with srv.client("engineer") as c:
        r = c.get(f"/api/v1/inspections/{older}")
    assert r.status_code == 200, r.text
    s = r.json()["surface"]
    assert s.get("blur_px") is None and (s["frames"], s["recentred"]) == (48, 3)
    assert len(s["defects"]) == len(DEFECTS)


def test_the_list_carries_no_surface(srv, records):
    with srv.client("mes") as c:
        items = c.get("/api/v1/inspections", params={"serial": "SN-SURF"}).json()["items"]
    assert len(items) == 1 and "surface" not in items[0]


def test_the_picture_needs_a_reader(srv, records):
    """Any role's token, and the panel's session cookie (its <img> sends no header);
    nobody else."""
    iid, _ = records["full"]
    url = f"/api/v1/inspections/{iid}/surface.png"
    for role in ROLES:
        with srv.client(role) as c:
            assert c.get(url).status_code == 200, role
    with srv.client(None) as c:
        r = c.get(url)
        assert r.status_code == 401 and not r.content.startswith(PNG_SIGNATURE)
        r = c.get(url, headers={"Authorization": "Bearer st_nonsense_token"})
        assert r.status_code == 401
        login = c.post("/api/v1/session", json={"token": srv.tokens["operator"]})
        assert login.status_code == 200, login.text
        assert SESSION_COOKIE in c.cookies
        r = c.get(url)
        assert r.status_code == 200 and r.content.startswith(PNG_SIGNATURE)
    with httpx.Client(base_url=srv.url, cookies={SESSION_COOKIE: "made-up"}) as c:
        assert c.get(url).status_code == 401


def test_a_changed_picture_is_not_served(srv, tmp_path):
    """Evidence: a picture whose file no longer matches its recorded SHA-256 is refused,
    saying so; a missing one is a 404 naming the file."""
    store = srv.runtime.store
    iid = store_surface_record(store, "SN-SURF-TAMPER", synthetic_surface(seed=3))
    path = store.image_path(store.get(iid).surface_image())
    url = f"/api/v1/inspections/{iid}/surface.png"
    with srv.client("admin") as c:
        assert c.get(url).status_code == 200
        path.write_bytes(path.read_bytes()[:-1] + b"\x00")
        r = c.get(url)
        assert r.status_code == 500 and "SHA-256" in r.json()["detail"]
        path.unlink()
        r = c.get(url)
        assert r.status_code == 404 and "missing from the data folder" in r.json()["detail"]


def test_the_schema_declares_the_surface(srv):
    with srv.client("admin") as c:
        schema = c.get("/openapi.json").json()
    comps = schema["components"]["schemas"]
    surface = comps["Inspection"]["properties"]["surface"]
    assert {"$ref": "#/components/schemas/Surface"} in surface["anyOf"]
    assert {"picture", "defects", "frames", "coverage"} <= set(comps["Surface"]["required"])
    assert "url" in comps["SurfacePicture"]["required"] and "rejects" in comps["SurfaceDefect"]["properties"]
    op = schema["paths"]["/api/v1/inspections/{inspection_id}/surface.png"]["get"]
    assert "image/png" in op["responses"]["200"]["content"] and "404" in op["responses"]


def test_a_job_order_may_ask_for_the_surface(srv, records, monkeypatch):
    """``surface`` of a job order reaches the station (true, false, absent: as the spec
    says); true for a spec without [surface] and a non-boolean are refused (422), and
    nothing is started. The station's start is replaced here: the scan itself is the
    e2e and browser tests' business."""
    iid, _ = records["full"]
    calls = []

    async def start(spec, serial, order_id, key, surface=None):
        calls.append((spec.part_number, serial, surface))
        return iid, False  # as a retried order: the existing inspection, nothing started

    monkeypatch.setattr(srv.runtime, "start_inspection", start)
    (srv.data_dir / "parts").mkdir(exist_ok=True)
    (srv.data_dir / "parts" / "NOSURF-1.toml").write_text(NO_SURFACE_SPEC)
    part = "ZDZG-22.2-12.3851"
    with srv.client("mes") as c:
        for asked in (True, False, None):
            body = {"part_number": part, "serial": "SN-ASK"} | ({} if asked is None else {"surface": asked})
            r = c.post("/api/v1/job-orders", json=body)
            assert r.status_code == 200 and r.json()["id"] == iid, r.text
        assert calls == [(part, "SN-ASK", True), (part, "SN-ASK", False), (part, "SN-ASK", None)]
        r = c.post("/api/v1/job-orders", json={"part_number": "NOSURF-1", "serial": "SN-ASK", "surface": True})
        assert r.status_code == 422 and r.json()["detail"] == ("part NOSURF-1 has no [surface] table: its surface "
                                                               "has no criteria to judge")
        r = c.post("/api/v1/job-orders", json={"part_number": part, "serial": "SN-ASK", "surface": "yes"})
        assert r.status_code == 422, r.text
        r = c.post("/api/v1/job-orders", json={"part_number": "NOSURF-1", "serial": "SN-ASK", "surface": False})
        assert r.status_code == 200, r.text
    assert calls[3:] == [("NOSURF-1", "SN-ASK", False)]
