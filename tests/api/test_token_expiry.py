"""Tokens that expire and are rotated, over REST (issue 22: "an expired token gets 401").

* A token past its ``expires_at`` gets 401 on every authenticated route, with a message
  that says it expired and when, never 403 (whatever its role) and never 429; whether
  the server had seen it before it expired or not. It cannot log in to the panel, and
  a panel session opened with it ends at the token's end.
* ``POST /api/v1/tokens/rotate``: the new token is shown once; old and new both work
  through the grace; the old one gets 401 after it; a rotated token cannot rotate again
  nor lengthen its life; a panel session cannot rotate (400); a rotation made with the
  CLI behind the server's back is seen within a second; audited without secrets.

Tokens are made fresh for each test through the store of the shared server, as
``station token create`` does; short lives (1-2 s) stand in for 90 days.
"""

from __future__ import annotations

import time
from datetime import datetime, timedelta

import httpx
import pytest

from api.auth import REVOCATION_CHECK_S
from api.sessions import CSRF_HEADER, SESSION_COOKIE
from station.store.models import utcnow
from station.store.tokens import TokenRepository
from tests.api.test_access_matrix import POLICY, PROBES, PUBLIC, Probe

#: a harmless write any mes/admin token is admitted to: refused for its content (422)
HARMLESS_WRITE = ("/api/v1/job-orders", {"part_number": "NO-SUCH-PART", "serial": "S"})


def _repo(api) -> TokenRepository:
    return TokenRepository(api.runtime.store)


def _bearer(token: str) -> dict[str, str]:
    return {"Authorization": f"Bearer {token}"}


def _wait_past(t: datetime) -> None:
    time.sleep(max(0.0, (t - utcnow()).total_seconds()) + 0.05)


def _at(text: str) -> datetime:
    return datetime.fromisoformat(text.replace("Z", "+00:00"))


def _status(api, token: str, method: str = "GET", url: str = "/api/v1/station", **kw) -> httpx.Response:
    with api.client(None) as c:
        return c.request(method, url, headers=_bearer(token), **kw)


def _write(api, token: str) -> httpx.Response:
    url, body = HARMLESS_WRITE
    return _status(api, token, "POST", url, json=body)


# ------------------------------------------------------------------------------ expiry
@pytest.fixture(scope="module")
def expired_tokens(api) -> dict[str, tuple[object, str]]:
    """An mes and an admin token that expired a moment ago; the server verified the
    mes one while it was valid (cached), the admin one never."""
    repo = _repo(api)
    # 3 s of life: the mes token's first use must come before it ends, on a loaded machine too
    made = {role: repo.create(role, name=f"expired {role}", expires_at=utcnow() + timedelta(seconds=3.0))
            for role in ("mes", "admin")}
    assert _status(api, made["mes"][1]).status_code == 200
    _wait_past(max(record.expires_at for record, _ in made.values()))
    return made


def _authenticated_cells():
    for (method, path), policy in POLICY.items():
        if policy == PUBLIC:
            continue
        for probe in PROBES.get((method, path), [Probe(path)]):
            yield pytest.param(method, probe, id=f"{method} {probe.url}")


@pytest.mark.parametrize("role", ["mes", "admin"])
@pytest.mark.parametrize("method, probe", list(_authenticated_cells()))
def test_an_expired_token_gets_401_saying_when_on_every_authenticated_route(api, expired_tokens, role, method,
                                                                          probe):
    record, token = expired_tokens[role]
    with httpx.Client(base_url=api.url, timeout=30.0) as c:
        with c.stream(method, probe.url, headers=_bearer(token), **probe.kwargs) as r:
            r.read()
    assert r.status_code == 401, f"{method} {probe.url} with an expired {role} token: {r.status_code} {r.text}"
    when = record.expires_at.isoformat(timespec="seconds")
    assert f"expired at {when}" in r.json()["detail"], r.text
    assert "invalid_token" in r.headers["www-authenticate"]


def test_an_expired_token_gets_401_on_a_read_and_a_write_route(api):
    repo = _repo(api)
    record, token = repo.create("mes", name="expiring MES", expires_at=utcnow() + timedelta(seconds=3.0))
    assert _status(api, token).status_code == 200
    assert _write(api, token).status_code == 422  # admitted (refused for its content)
    _wait_past(record.expires_at)
    read, write = _status(api, token), _write(api, token)
    assert read.status_code == write.status_code == 401
    assert "the API token expired at" in read.json()["detail"] and "expired at" in write.json()["detail"]
    # an operator's route: an expired mes token is told it expired, not that its role may not
    assert _status(api, token, "POST", "/api/v1/station/pause").status_code == 401


def test_an_expired_token_cannot_log_in_to_the_panel(api, expired_tokens):
    _record, token = expired_tokens["admin"]
    with httpx.Client(base_url=api.url, timeout=30.0) as c:
        r = c.post("/api/v1/session", json={"token": token})
    assert r.status_code == 401 and "expired at" in r.json()["detail"]


def test_a_panel_session_ends_when_its_token_expires(api):
    # 6 s of life: the session, a read and an admitted command must come before it ends
    # (2 s was too short on a loaded 2-core machine with PostgreSQL: the command came late)
    record, token = _repo(api).create("operator", name="badge, expiring",
                                      expires_at=utcnow() + timedelta(seconds=6.0))
    with httpx.Client(base_url=api.url, timeout=30.0) as c:
        r = c.post("/api/v1/session", json={"token": token})
        assert r.status_code == 200, r.text
        body = r.json()
        # the session says it ends with the token (not 12 h on), and the browser forgets the cookie then
        assert abs((_at(body["expires_at"]) - record.expires_at).total_seconds()) < 1.0
        max_age = int(r.headers["set-cookie"].lower().split("max-age=")[1].split(";")[0])
        remaining = (record.expires_at - utcnow()).total_seconds()
        assert 1 <= max_age <= 6 and abs(max_age - remaining) <= 1.5, (max_age, remaining)
        csrf, cookie = body["csrf_token"], c.cookies[SESSION_COOKIE]
        assert c.get("/api/v1/station").status_code == 200
        assert c.post("/api/v1/station/pause", headers={CSRF_HEADER: csrf}).status_code == 409  # admitted
        _wait_past(record.expires_at)
    # a browser has dropped the cookie by now (Max-Age); the server refuses it anyway
    with httpx.Client(base_url=api.url, timeout=30.0, headers={"Cookie": f"{SESSION_COOKIE}={cookie}"}) as c:
        r = c.get("/api/v1/station")
        assert r.status_code == 401 and "session's token expired at" in r.json()["detail"], r.text
        r = c.post("/api/v1/station/pause", headers={CSRF_HEADER: csrf})
        assert r.status_code == 401 and "session has ended" in r.json()["detail"]  # gone, not refused again


# ---------------------------------------------------------------------------- rotation
def test_rotation_over_the_api_keeps_both_tokens_working_through_the_grace(api):
    record, old = _repo(api).create("mes", name="rotating MES")
    before = utcnow()
    r = _status(api, old, "POST", "/api/v1/tokens/rotate", json={"grace_s": 4.0})
    assert r.status_code == 200, r.text
    assert r.headers["cache-control"] == "no-store"
    body = r.json()
    new = body["token"]
    assert new.startswith(f"st_{body['prefix']}_") and new != old
    assert (body["role"], body["name"], body["expires_at"]) == ("mes", "rotating MES", None)
    assert body["old"]["id"] == record.id and body["old"]["prefix"] == record.prefix
    old_end = _at(body["old"]["expires_at"])
    assert before + timedelta(seconds=3.9) <= old_end <= utcnow() + timedelta(seconds=4.1)
    # the switch-over: both tokens read and write
    for token in (old, new):
        assert _status(api, token).status_code == 200
        assert _write(api, token).status_code == 422
    _wait_past(old_end)
    gone = _status(api, old)
    assert gone.status_code == 401 and "expired at" in gone.json()["detail"]
    assert _write(api, old).status_code == 401
    assert _status(api, new).status_code == 200 and _write(api, new).status_code == 422


def test_a_rotated_token_cannot_extend_itself(api):
    lifetime = timedelta(hours=1)
    record, old = _repo(api).create("mes", name="short-lived MES", expires_at=utcnow() + lifetime)
    # a week's grace does not push the old token's end past its own expiry
    r = _status(api, old, "POST", "/api/v1/tokens/rotate", json={"grace_s": 7 * 86400})
    assert r.status_code == 200, r.text
    body = r.json()
    assert _at(body["old"]["expires_at"]) == record.expires_at.replace(microsecond=record.expires_at.microsecond)
    # the new token lives as long as the old one was made to, from now: no longer
    new_end = _at(body["expires_at"])
    assert abs((new_end - (utcnow() + lifetime)).total_seconds()) < 5.0
    # the rotated-from token cannot rotate again (to gain another grace, or another token)
    again = _status(api, old, "POST", "/api/v1/tokens/rotate", json={"grace_s": 600})
    assert again.status_code == 409 and "already rotated" in again.json()["detail"]
    assert _repo(api).get(record.id).expires_at == record.expires_at
    # nor can its successor make itself a longer-lived token, or one without an end
    new = body["token"]
    longer = _status(api, new, "POST", "/api/v1/tokens/rotate", json={"expires_in_s": 2 * 3600})
    assert longer.status_code == 422 and "lives longer" in longer.json()["detail"]
    assert _status(api, new, "POST", "/api/v1/tokens/rotate", json={"grace_s": 8 * 86400}).status_code == 422
    assert _status(api, new, "POST", "/api/v1/tokens/rotate", json={"grace": 5}).status_code == 422  # unknown field
    assert _status(api, new).status_code == 200  # the refusals changed nothing


def test_a_panel_session_cannot_rotate(api):
    _record, token = _repo(api).create("operator", name="badge, no rotation")
    with httpx.Client(base_url=api.url, timeout=30.0) as c:
        csrf = c.post("/api/v1/session", json={"token": token}).json()["csrf_token"]
        r = c.post("/api/v1/tokens/rotate", headers={CSRF_HEADER: csrf})
        assert r.status_code == 400 and "panel session" in r.json()["detail"]
        assert c.post("/api/v1/tokens/rotate").status_code == 403  # and without its CSRF token, as every write
    assert _status(api, token).status_code == 200  # not rotated


def test_a_rotation_with_the_cli_is_seen_within_a_second(api):
    repo = _repo(api)
    record, old = repo.create("mes", name="MES rotated by the admin")
    assert _status(api, old).status_code == 200  # known to the server
    _was, _new_record, new = repo.rotate(record.id, grace_s=0.0)  # as `station token rotate --grace 0s`
    done = time.monotonic()
    while (r := _status(api, old)).status_code != 401:
        assert time.monotonic() - done < REVOCATION_CHECK_S + 1.0, "the rotated-away token still works"
        time.sleep(0.05)
    assert "expired at" in r.json()["detail"]
    assert _status(api, new).status_code == 200


def test_rotation_is_audited_without_secrets(api):
    record, old = _repo(api).create("mes", name="audited MES")
    r = _status(api, old, "POST", "/api/v1/tokens/rotate", json={"grace_s": 60})
    assert r.status_code == 200
    new = r.json()["token"]
    events = [e.message for e in api.runtime.store.events(kind="audit", limit=200)]
    mine = [m for m in events if f"token {record.id} (audited MES" in m and "rotated" in m]
    assert len(mine) == 1, events[:10]
    assert f"by audited MES (token {record.id}, mes) over the API" in mine[0]
    assert f"st_{r.json()['prefix']}_..." in mine[0]
    text = "\n".join(events)
    for token in (old, new):
        assert token not in text and token[len("st_") + 16 + 1:] not in text
