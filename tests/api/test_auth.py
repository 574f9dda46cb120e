"""Every endpoint against every role and no token (table-driven): no write without a
token, no write with the wrong role; reads need any valid token; probes need none.

Requests that pass the role check carry a body or path that the endpoint refuses
(422, 404, 409), so the table changes nothing on the station.
"""

from __future__ import annotations

import uuid

import pytest

from tests.api.conftest import ROLES

ANY = "any"  # any valid token
PUBLIC = "public"  # no token needed

#: (method, path as requested, route path, who may)
TABLE = [
    ("POST", "/api/v1/job-orders", "/api/v1/job-orders", {"mes", "operator"}),
    ("GET", "/api/v1/inspections", "/api/v1/inspections", ANY),
    ("GET", f"/api/v1/inspections/{uuid.uuid4()}", "/api/v1/inspections/{inspection_id}", ANY),
    ("GET", f"/api/v1/inspections/{uuid.uuid4()}/qif", "/api/v1/inspections/{inspection_id}/qif", ANY),
    ("GET", "/api/v1/station", "/api/v1/station", ANY),
    ("GET", "/api/v1/axes", "/api/v1/axes", ANY),
    ("GET", "/api/v1/alarms", "/api/v1/alarms", ANY),
    ("POST", "/api/v1/station/pause", "/api/v1/station/{command}", {"operator"}),
    ("POST", "/api/v1/station/abort", "/api/v1/station/{command}", {"operator"}),
    ("GET", "/api/v1/parts", "/api/v1/parts", ANY),
    ("GET", "/api/v1/parts/ZDZG-22.2-12.3851", "/api/v1/parts/{part_number}", ANY),
    ("PUT", "/api/v1/parts/AUTH-1", "/api/v1/parts/{part_number}", {"engineer"}),
    ("GET", "/api/v1/models", "/api/v1/models", ANY),
    ("POST", "/api/v1/models", "/api/v1/models", {"engineer"}),
    ("POST", "/api/v1/models/999999/activate", "/api/v1/models/{version}/activate", {"engineer"}),
    ("GET", "/api/v1/calibrations", "/api/v1/calibrations", ANY),
    ("POST", "/api/v1/calibrations", "/api/v1/calibrations", {"engineer"}),
    ("POST", "/api/v1/calibrations/999999/activate", "/api/v1/calibrations/{version}/activate", {"engineer"}),
    ("POST", "/api/v1/reports/iso230", "/api/v1/reports/iso230", {"engineer"}),
    ("POST", "/api/v1/reports/discovery", "/api/v1/reports/discovery", {"engineer"}),
    ("GET", "/api/v1/reports/discovery", "/api/v1/reports/discovery", ANY),
    ("GET", f"/api/v1/reports/discovery/{uuid.uuid4()}", "/api/v1/reports/discovery/{report_id}", ANY),
    ("GET", "/api/v1/models/active/curves", "/api/v1/models/active/curves", ANY),
    ("POST", "/api/v1/session", "/api/v1/session", PUBLIC),
    ("GET", "/api/v1/session", "/api/v1/session", ANY),
    ("DELETE", "/api/v1/session", "/api/v1/session", ANY),
    ("GET", "/api/v1/events", "/api/v1/events", ANY),
    ("GET", "/api/v1/camera.mjpg", "/api/v1/camera.mjpg", ANY),
    ("GET", "/metrics", "/metrics", ANY),
    ("GET", "/healthz", "/healthz", PUBLIC),
    ("GET", "/readyz", "/readyz", PUBLIC),
]

#: bodies that pass the role check but are refused (nothing happens)
BODIES = {"/api/v1/job-orders": {"json": {"part_number": "NO-SUCH-PART", "serial": "S"}},
          "/api/v1/parts/AUTH-1": {"json": {"part_number": "AUTH-1"}},
          "/api/v1/session": {"json": {}}}


def test_the_table_covers_every_route(api):
    paths = api.app.openapi()["paths"]
    routes = {(m.upper(), p) for p, ops in paths.items() for m in ops}
    assert routes == {(m, route) for m, _path, route, _who in TABLE}


def _call(api, method: str, path: str, role: str | None, token: str | None = None):
    headers = {}
    if token is not None:
        headers["Authorization"] = f"Bearer {token}"
    elif role is not None:
        headers["Authorization"] = f"Bearer {api.tokens[role]}"
    with api.client(None) as c:
        with c.stream(method, path, headers=headers, **BODIES.get(path, {})) as r:
            return r.status_code  # streams (SSE, MJPEG) are closed unread


@pytest.mark.parametrize("role", [None, *ROLES])
@pytest.mark.parametrize("method, path, route, who", TABLE, ids=[f"{m} {p}" for m, p, _r, _w in TABLE])
def test_role_table(api, method, path, route, who, role):
    status = _call(api, method, path, role)
    if who == PUBLIC:
        assert status not in (401, 403)
    elif role is None:
        assert status == 401
    elif who == ANY or role in who or role == "admin":
        assert status not in (401, 403), status
        if method != "GET":
            assert status in (404, 409, 422), status  # refused for its content, not its caller
    else:
        assert status == 403


@pytest.mark.parametrize("token", ["nonsense", "Basic", "st_0123456789abcdef_" + "x" * 43])
def test_bad_tokens_are_401(api, token):
    assert _call(api, "GET", "/api/v1/station", None, token=token) == 401


def test_a_revoked_token_is_refused(api):
    from station.store.tokens import TokenRepository

    repo = TokenRepository(api.runtime.store)
    record, token = repo.create("operator", name="short-lived")
    assert _call(api, "GET", "/api/v1/station", None, token=token) == 200
    repo.revoke(record.id)
    assert _call(api, "GET", "/api/v1/station", None, token=token) == 401


def test_tokens_are_stored_hashed(api):
    import sqlite3

    con = sqlite3.connect(api.data_dir / "station.db")
    try:
        rows = con.execute("SELECT salt, token_hash, prefix FROM api_token").fetchall()
    finally:
        con.close()
    dump = repr(rows)
    for token in api.tokens.values():
        secret = token[len("st_") + 16 + 1:]  # the part after the public prefix
        assert token not in dump and secret not in dump
    assert len({salt for salt, _h, _p in rows}) == len(rows)  # a salt per token
