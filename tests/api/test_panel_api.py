"""The panel's side of the API: browser login (cookie session + CSRF token), logout,
the active model's curves, stored discovery reports, setpoints in /axes, the panel's
static files and their headers."""

from __future__ import annotations

import httpx

from api.sessions import CSRF_HEADER, SESSION_COOKIE


def _browser(api) -> httpx.Client:
    """A client that behaves like the panel: cookies, no Authorization header."""
    return httpx.Client(base_url=api.url, timeout=30.0)


def _login(c: httpx.Client, token: str) -> dict:
    r = c.post("/api/v1/session", json={"token": token})
    assert r.status_code == 200, r.text
    return r.json()


def test_login_sets_a_hardened_cookie_and_returns_a_csrf_token(api):
    with _browser(api) as c:
        r = c.post("/api/v1/session", json={"token": api.tokens["operator"]})
        assert r.status_code == 200, r.text
        body = r.json()
        assert body["role"] == "operator" and body["kind"] == "session" and len(body["csrf_token"]) >= 32
        cookie = r.headers["set-cookie"]
        assert cookie.startswith(f"{SESSION_COOKIE}=")
        low = cookie.lower()
        assert "httponly" in low and "samesite=strict" in low and "path=/" in low
        assert "secure" not in low  # plain http on 127.0.0.1; https sets it
        assert body["csrf_token"] not in cookie
        # the session reads, and tells its CSRF token again
        me = c.get("/api/v1/session").json()
        assert me["name"] == "test operator" and me["csrf_token"] == body["csrf_token"]
        assert c.get("/api/v1/station").status_code == 200


def test_a_cookie_write_needs_the_csrf_token(api):
    with _browser(api) as c:
        csrf = _login(c, api.tokens["operator"])["csrf_token"]
        # nothing runs: pause is refused for its state (409) once the caller is admitted
        assert c.post("/api/v1/station/pause").status_code == 403
        assert c.post("/api/v1/station/pause", headers={CSRF_HEADER: "wrong"}).status_code == 403
        assert c.post("/api/v1/station/pause", headers={CSRF_HEADER: csrf}).status_code == 409
        # roles still apply to sessions: an operator may not change part specs
        assert c.put("/api/v1/parts/CSRF-1", json={"part_number": "CSRF-1"},
                     headers={CSRF_HEADER: csrf}).status_code == 403


def test_an_operator_may_order_a_job_and_a_bad_order_is_still_refused(api):
    with _browser(api) as c:
        csrf = _login(c, api.tokens["operator"])["csrf_token"]
        r = c.post("/api/v1/job-orders", json={"part_number": "NO-SUCH-PART", "serial": "S"},
                   headers={CSRF_HEADER: csrf, "Idempotency-Key": "panel-test-1"})
        assert r.status_code == 422


def test_bad_logins_and_foreign_origins_are_refused(api):
    with _browser(api) as c:
        assert c.post("/api/v1/session", json={"token": "st_0123456789abcdef_" + "x" * 43}).status_code == 401
        assert c.post("/api/v1/session", json={"token": api.tokens["operator"]},
                      headers={"Origin": "http://evil.example"}).status_code == 403
        assert c.post("/api/v1/session", json={"token": api.tokens["operator"]},
                      headers={"Origin": api.url}).status_code == 200


def test_logout_ends_the_session_on_the_server(api):
    with _browser(api) as c:
        csrf = _login(c, api.tokens["operator"])["csrf_token"]
        stolen = c.cookies[SESSION_COOKIE]
        assert c.delete("/api/v1/session").status_code == 403  # logout is a write: CSRF too
        assert c.delete("/api/v1/session", headers={CSRF_HEADER: csrf}).status_code == 200
        assert c.get("/api/v1/station").status_code == 401
    # the old cookie value is worthless now
    with httpx.Client(base_url=api.url, cookies={SESSION_COOKIE: stolen}) as other:
        assert other.get("/api/v1/station").status_code == 401


def test_a_revoked_token_ends_its_sessions(api, monkeypatch):
    from api import auth
    from station.store.tokens import TokenRepository

    repo = TokenRepository(api.runtime.store)
    record, token = repo.create("operator", name="leaving")
    monkeypatch.setattr(auth, "RECHECK_S", 0.0)  # check at once rather than within 30 s
    with _browser(api) as c:
        _login(c, token)
        assert c.get("/api/v1/station").status_code == 200
        repo.revoke(record.id)
        assert c.get("/api/v1/station").status_code == 401


def test_bearer_tokens_are_unchanged_and_have_no_session_to_end(api):
    with api.client("mes") as c:
        me = c.get("/api/v1/session").json()
        assert me == {"name": "test mes", "role": "mes", "token_id": me["token_id"], "kind": "token"}
        assert c.delete("/api/v1/session").status_code == 404


def test_the_active_models_curves(api):
    with api.client("operator") as c:
        r = c.get("/api/v1/models/active/curves")
    assert r.status_code == 200, r.text
    body = r.json()
    z, cax = body["axes"]["Z"], body["axes"]["C"]
    assert set(z["curves"]) == {"EXZ", "EYZ", "EZZ", "EAZ", "EBZ", "ECZ"}
    assert set(cax["curves"]) == {"EXC", "EYC", "EZC", "EAC", "EBC", "ECC"}
    assert cax["positions"][0] == 0 and cax["positions"][-1] == 360
    for curve in z["curves"].values():
        assert len(curve["values"]) == len(z["positions"])
    ezz = body["compensation_tables"]["EZZ"]
    assert ezz["correction"] == [-d for d in ezz["deviation"]]
    # the table's points lie on the sampled curve (same model, same convention)
    model = api.runtime.station.model
    import numpy as np

    x = np.asarray(z["positions"])
    assert np.allclose(z["curves"]["EZZ"]["values"], model.motions_of("Z").z.evaluate(x, np.ones_like(x)), atol=1e-3)


def test_discovery_reports_are_stored_and_listed(api):
    from station.discovery.synth import Campaign, linear_model, make_recording
    from station.effects import Backlash

    rec = make_recording(linear_model(), (Backlash(4.0),), Campaign(seed=5))
    model_toml = ('[axis]\nname = "Z"\nkind = "linear"\n\n[baseline]\ntarget = [0.0, 60.0, 120.0]\n'
                  'deviation = [0.0, 9.0, 18.0]\n\n[noise]\nsigma = 0.5\n')
    with api.client("engineer") as c:
        r = c.post("/api/v1/reports/discovery", files={"model": ("m.toml", model_toml), "recording": ("r.csv", rec.to_csv())})
        assert r.status_code == 200, r.text
        location = r.headers["location"]
        stored = c.get(location).json()
        assert stored["report"] == r.json()
        assert stored["created_by"] == "test engineer" and stored["model_file"] == "m.toml"
        listing = c.get("/api/v1/reports/discovery").json()
        ids = [e["id"] for e in listing["items"]]
        assert stored["id"] in ids
        summary = listing["items"][ids.index(stored["id"])]
        assert "backlash" in summary["effects"] and summary["rms_after"] < summary["rms_before"]
        assert c.get("/api/v1/reports/discovery/not-a-uuid").status_code == 422
        assert c.get("/api/v1/reports/discovery/00000000-0000-4000-8000-000000000000").status_code == 404


def test_axes_show_setpoints(api):
    with api.client("operator") as c:
        body = c.get("/api/v1/axes").json()
    for axis in ("Z", "C"):
        assert "setpoint" in body[axis]


def test_the_panel_is_served_with_its_headers(api):
    with httpx.Client(base_url=api.url) as c:
        r = c.get("/", follow_redirects=False)
        assert r.status_code == 303 and r.headers["location"] == "/panel/"
        page = c.get("/panel/")
        assert page.status_code == 200 and "Bore inspection station" in page.text
        csp = page.headers["content-security-policy"]
        assert "script-src 'self'" in csp and "frame-ancestors 'none'" in csp
        assert page.headers["x-frame-options"] == "DENY"
        for path in ("/panel/login.html", "/panel/panel.css", "/panel/js/app.js", "/panel/js/api.js",
                     "/panel/js/plots.js", "/panel/js/login.js"):
            assert c.get(path).status_code == 200, path
