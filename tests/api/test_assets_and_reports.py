"""Compensation models and calibrations (upload, validate, list, activate, audit) and
the report endpoints (ISO 230-2, discovery)."""

from __future__ import annotations

import json
from importlib import resources


from tests.api.conftest import wait_idle

ISO_CSV = """# axis: Z
# kind: linear
time_s,run,direction,target,deviation
0,1,+1,0,1.0
1,1,+1,10,2.0
2,1,+1,20,3.0
3,1,-1,20,1.0
4,1,-1,10,0.0
5,1,-1,0,-1.0
6,2,+1,0,2.0
7,2,+1,10,4.0
8,2,+1,20,3.0
9,2,-1,20,2.0
10,2,-1,10,1.0
11,2,-1,0,0.0
"""


def test_model_upload_validate_activate_and_audit(api):
    text = resources.files("station").joinpath("data/default_station.toml").read_text()
    with api.client("engineer") as c:
        wait_idle(c)
        r = c.post("/api/v1/models", files={"file": ("default.toml", text)}, data={"name": "as shipped"})
        assert r.status_code == 201, r.text
        version = r.json()["version"]
        assert r.json()["uploaded_by"] == "test engineer" and len(r.json()["sha256"]) == 64
        bad = c.post("/api/v1/models", files={"file": ("bad.toml", "[motions.nobody]\nx = 1\n")})
        assert bad.status_code == 422 and "bad.toml" in bad.json()["detail"]
        not_toml = c.post("/api/v1/models", files={"file": ("x.toml", "= =")})
        assert not_toml.status_code == 422 and "TOML" in not_toml.json()["detail"]
        big = c.post("/api/v1/models", files={"file": ("big.toml", "#" * (1024 * 1024 + 1))})
        assert big.status_code == 413
        listing = c.get("/api/v1/models").json()
        assert [v["version"] for v in listing["items"]] == [version]  # refused uploads left nothing
        assert listing["active"] is None
        r = c.post(f"/api/v1/models/{version}/activate")
        assert r.status_code == 200 and r.json()["active"] is True
        assert c.get("/api/v1/models").json()["active"] == version
        assert c.post("/api/v1/models/12345/activate").status_code == 404
    audit = [e.message for e in api.runtime.store.events(kind="audit", limit=100)]
    assert any(f"uploaded compensation model version {version}" in m for m in audit)
    assert any(f"activated compensation model version {version}" in m and "test engineer" in m for m in audit)


def test_calibration_upload_and_activate_sets_the_scale(api):
    rt = api.runtime
    scale = rt.station.mm_per_px  # the same scale: the other tests' inspections stay right
    cal = {"camera_matrix": [[1000.0, 0, 640], [0, 1000.0, 512], [0, 0, 1]], "dist_coeffs": [0.0, 0.0, 0.0, 0.0],
           "image_size": [1280, 1024], "rms_px": 0.1, "mm_per_px": scale}
    with api.client("engineer") as c:
        wait_idle(c)
        r = c.post("/api/v1/calibrations", files={"file": ("cal.json", json.dumps(cal))})
        assert r.status_code == 201, r.text
        v = r.json()["version"]
        bad = c.post("/api/v1/calibrations", files={"file": ("cal.json", json.dumps({"camera_matrix": [1, 2]}))})
        assert bad.status_code == 422
        rt.station.mm_per_px = scale * 2  # changed under us: activation must set it back
        assert c.post(f"/api/v1/calibrations/{v}/activate").status_code == 200
    assert rt.station.mm_per_px == scale


def test_iso230_report(api):
    with api.client("engineer") as c:
        r = c.post("/api/v1/reports/iso230", files={"recording": ("rec.csv", ISO_CSV)})
        assert r.status_code == 200, r.text
        out = r.json()
        assert out["B"] == 2.5 and out["E"] == 3.5 and out["unit"] == "um" and len(out["targets"]) == 3
        bad = c.post("/api/v1/reports/iso230", files={"recording": ("rec.csv", "time_s,run\n0,x\n")})
        assert bad.status_code == 422 and "rec.csv" in bad.json()["detail"]


def test_discovery_report(api):
    from station.discovery.synth import Campaign, linear_model, make_recording
    from station.effects import Backlash

    rec = make_recording(linear_model(), (Backlash(4.0),), Campaign(seed=3))
    model_toml = """[axis]
name = "Z"
kind = "linear"

[baseline]
target = [0.0, 20.0, 40.0, 60.0, 80.0, 100.0, 120.0]
deviation = [0.0, 3.1, 6.0, 9.2, 12.1, 15.3, 18.0]

[noise]
sigma = 0.5
"""
    with api.client("admin") as c:
        r = c.post("/api/v1/reports/discovery",
                   files={"model": ("z.toml", model_toml), "recording": ("z.csv", rec.to_csv())})
        assert r.status_code == 200, r.text
        report = r.json()
        assert report["after"]["rms"] < report["before"]["rms"]
        assert any(e["name"] == "backlash" for e in report["effects"])
        bad = c.post("/api/v1/reports/discovery", files={"model": ("z.toml", "[axis]\n"),
                                                          "recording": ("z.csv", rec.to_csv())})
        assert bad.status_code == 422
