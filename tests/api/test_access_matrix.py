"""Who may call what: every route of the app against every kind of caller.

The routes come from the app itself (``app.routes``, included routers and mounts
resolved), and ``POLICY`` must name exactly those: a new route without a policy entry
fails ``test_the_policy_covers_exactly_the_apps_routes``. Each cell of the matrix
(route x caller) is one test:

* callers without a valid credential (no header, a garbage / unknown / tampered /
  Basic token, a made-up session cookie) get 401 on every non-public route;
* an API token (``Authorization: Bearer``) or a panel session (cookie; the CSRF
  header on writes only) of a role the policy admits gets past the auth layer (not
  401/403, not 5xx); another role gets 403;
* a panel session without its CSRF header, or with another session's, gets 403 on
  every write, whatever its role;
* public routes (probes, the login, the panel's files, the API's own docs) answer
  every caller without 401/403.

The requests that pass the auth layer are refused for their content (an unknown
part, a missing file, an unknown version: 404/409/422), so the matrix changes nothing
on the station (docs/security.md).
"""

from __future__ import annotations

import uuid
from dataclasses import dataclass, field

import httpx
import pytest

from api.sessions import CSRF_HEADER, SESSION_COOKIE
from tests.api.conftest import ROLES, wait_idle

PUBLIC = "public"
ANY = frozenset(ROLES)


def roles(*names: str) -> frozenset[str]:
    """The roles named, and admin (who may do everything)."""
    return frozenset(names) | {"admin"}


#: (method, route path) -> who may call it; route paths as the app declares them
POLICY: dict[tuple[str, str], frozenset[str] | str] = {
    # the API's own documentation (the schema of an open-source API: nothing secret)
    ("GET", "/openapi.json"): PUBLIC,
    ("GET", "/docs"): PUBLIC,
    ("GET", "/docs/oauth2-redirect"): PUBLIC,
    ("GET", "/redoc"): PUBLIC,
    # the panel: its static files and the redirect to them; the login itself
    ("GET", "/"): PUBLIC,
    ("GET", "/panel"): PUBLIC,
    ("POST", "/api/v1/session"): PUBLIC,
    # probes for systemd / a load balancer: no data, no commands
    ("GET", "/healthz"): PUBLIC,
    ("GET", "/readyz"): PUBLIC,
    # reads: any valid token
    ("GET", "/metrics"): ANY,
    ("GET", "/api/v1/session"): ANY,
    ("DELETE", "/api/v1/session"): ANY,
    ("GET", "/api/v1/inspections"): ANY,
    ("GET", "/api/v1/stations"): ANY,
    ("GET", "/api/v1/inspections/{inspection_id}"): ANY,
    ("GET", "/api/v1/inspections/{inspection_id}/qif"): ANY,
    ("GET", "/api/v1/inspections/{inspection_id}/surface.png"): ANY,
    ("GET", "/api/v1/station"): ANY,
    ("GET", "/api/v1/axes"): ANY,
    ("GET", "/api/v1/alarms"): ANY,
    ("GET", "/api/v1/parts"): ANY,
    ("GET", "/api/v1/parts/{part_number}"): ANY,
    ("GET", "/api/v1/models"): ANY,
    ("GET", "/api/v1/calibrations"): ANY,
    ("GET", "/api/v1/models/active/curves"): ANY,
    ("GET", "/api/v1/reports/discovery"): ANY,
    ("GET", "/api/v1/reports/discovery/{report_id}"): ANY,
    ("GET", "/api/v1/reports/discovery/{report_id}/plots/{name}"): ANY,
    ("GET", "/api/v1/events"): ANY,
    ("GET", "/api/v1/camera.mjpg"): ANY,
    ("GET", "/api/v1/checks/{check_id}"): ANY,
    ("GET", "/api/v1/calibrations/master/{run_id}"): ANY,
    ("GET", "/api/v1/model-proposals"): ANY,
    ("GET", "/api/v1/model-proposals/{proposal_id}"): ANY,
    ("GET", "/api/v1/model-proposals/{proposal_id}/plot"): ANY,
    # writes
    ("POST", "/api/v1/job-orders"): roles("mes", "operator"),
    ("POST", "/api/v1/station/{command}"): roles("operator"),
    # a check on the master: whoever works at the machine, not the MES
    ("POST", "/api/v1/checks"): roles("operator", "engineer"),
    ("POST", "/api/v1/model-proposals/{proposal_id}/approve"): roles("engineer"),
    ("POST", "/api/v1/model-proposals/{proposal_id}/reject"): roles("engineer"),
    ("PUT", "/api/v1/parts/{part_number}"): roles("engineer"),
    ("POST", "/api/v1/models"): roles("engineer"),
    ("POST", "/api/v1/models/{version}/activate"): roles("engineer"),
    ("POST", "/api/v1/calibrations"): roles("engineer"),
    ("POST", "/api/v1/calibrations/{version}/activate"): roles("engineer"),
    # a self-calibration on the artefact: the station's model is an engineer's
    ("POST", "/api/v1/calibrations/master"): roles("engineer"),
    ("POST", "/api/v1/reports/iso230"): roles("engineer"),
    ("POST", "/api/v1/reports/discovery"): roles("engineer"),
    # a client swaps its own token (a panel session has none of its own: 400)
    ("POST", "/api/v1/tokens/rotate"): ANY,
}


@dataclass(frozen=True)
class Probe:
    """A concrete request for a route: harmless for whoever gets past the auth layer."""

    url: str
    kwargs: dict = field(default_factory=dict, hash=False, compare=False)


def _absent_id(what: str) -> uuid.UUID:
    """An id no record has, the same in every process that collects the tests (the
    probes name the tests, and pytest-xdist's workers must collect the same ones)."""
    return uuid.uuid5(uuid.NAMESPACE_URL, f"bore-station-tests/absent/{what}")


#: concrete requests for routes with path parameters or bodies (the rest: the path itself)
PROBES: dict[tuple[str, str], list[Probe]] = {
    ("GET", "/panel"): [Probe("/panel/"), Probe("/panel/login.html"), Probe("/panel/js/api.js")],
    ("POST", "/api/v1/session"): [Probe("/api/v1/session", {"json": {}})],  # 422: no token in the body
    ("GET", "/api/v1/inspections/{inspection_id}"): [Probe(f"/api/v1/inspections/{_absent_id('inspection')}")],
    ("GET", "/api/v1/inspections/{inspection_id}/qif"): [Probe(f"/api/v1/inspections/{_absent_id('inspection-qif')}/qif")],
    ("GET", "/api/v1/inspections/{inspection_id}/surface.png"): [Probe(f"/api/v1/inspections/{_absent_id('inspection-surface')}/surface.png")],
    ("GET", "/api/v1/parts/{part_number}"): [Probe("/api/v1/parts/ZDZG-22.2-12.3851")],
    ("GET", "/api/v1/reports/discovery/{report_id}"): [Probe(f"/api/v1/reports/discovery/{_absent_id('report')}")],
    ("GET", "/api/v1/reports/discovery/{report_id}/plots/{name}"): [
        Probe(f"/api/v1/reports/discovery/{_absent_id('report-plots')}/plots/residual_position.png")],
    # 422: no such part (the part is looked up only after the caller is admitted)
    ("POST", "/api/v1/job-orders"): [Probe("/api/v1/job-orders",
                                           {"json": {"part_number": "NO-SUCH-PART", "serial": "S"}})],
    ("GET", "/api/v1/checks/{check_id}"): [Probe(f"/api/v1/checks/{_absent_id('check')}")],
    ("GET", "/api/v1/calibrations/master/{run_id}"): [Probe("/api/v1/calibrations/master/0123456789ab")],
    # 422: poses below 1 (validated only after the caller is admitted)
    ("POST", "/api/v1/calibrations/master"): [Probe("/api/v1/calibrations/master", {"json": {"poses": 0}})],
    ("GET", "/api/v1/model-proposals/{proposal_id}"): [Probe("/api/v1/model-proposals/0123456789ab")],
    ("GET", "/api/v1/model-proposals/{proposal_id}/plot"): [Probe("/api/v1/model-proposals/0123456789ab/plot")],
    # 422: no such kind of check; 404: no such proposal
    ("POST", "/api/v1/checks"): [Probe("/api/v1/checks", {"json": {"kind": "nonsense"}})],
    ("POST", "/api/v1/model-proposals/{proposal_id}/approve"): [Probe("/api/v1/model-proposals/0123456789ab/approve")],
    ("POST", "/api/v1/model-proposals/{proposal_id}/reject"): [Probe("/api/v1/model-proposals/0123456789ab/reject",
                                                                      {"json": {"note": "matrix"}})],
    # 409 on an idle station; the station is made idle before the matrix runs
    ("POST", "/api/v1/station/{command}"): [Probe("/api/v1/station/pause")],
    # 422: a spec without bore and holes
    ("PUT", "/api/v1/parts/{part_number}"): [Probe("/api/v1/parts/MATRIX-1", {"json": {"part_number": "MATRIX-1"}})],
    # 422: not TOML / not JSON / not a recording; 404: no such version
    ("POST", "/api/v1/models"): [Probe("/api/v1/models", {"files": {"file": ("m.toml", "= =")}})],
    ("POST", "/api/v1/calibrations"): [Probe("/api/v1/calibrations", {"files": {"file": ("c.json", "{")}})],
    ("POST", "/api/v1/models/{version}/activate"): [Probe("/api/v1/models/999999/activate")],
    ("POST", "/api/v1/calibrations/{version}/activate"): [Probe("/api/v1/calibrations/999999/activate")],
    ("POST", "/api/v1/reports/iso230"): [Probe("/api/v1/reports/iso230", {"files": {"recording": ("r.csv", "x")}})],
    # 422: the recording is missing (found before the discovery code is even loaded)
    ("POST", "/api/v1/reports/discovery"): [Probe("/api/v1/reports/discovery", {"files": {"model": ("m.toml", "= =")}})],
    # 422: a negative grace (the matrix's tokens are not rotated)
    ("POST", "/api/v1/tokens/rotate"): [Probe("/api/v1/tokens/rotate", {"json": {"grace_s": -1}})],
}

#: what an admitted write answers (it is refused for its content: nothing changes);
#: logging out with a session really ends that (fresh) session
WRITE_ANSWERS: dict[tuple[str, str], set[int]] = {
    ("DELETE", "/api/v1/session"): {200, 404},
}
REFUSED_FOR_CONTENT = {404, 409, 422}

SAFE = {"GET", "HEAD", "OPTIONS"}


def app_routes(app) -> set[tuple[str, str]]:
    """Every (method, path) the app answers: included routers resolved (FastAPI >=
    0.16x keeps them nested), mounts as GET of their prefix; HEAD is folded into GET."""
    try:
        from fastapi.routing import iter_route_contexts
    except ImportError:  # older FastAPI: app.routes is flat
        routes = list(app.routes)
    else:
        routes = list(iter_route_contexts(app.routes))
    out = set()
    for r in routes:
        methods = getattr(r, "methods", None) or {"GET"}  # a Mount (static files) has none
        path = r.path
        for m in methods:
            if m == "HEAD" and "GET" in methods:
                continue
            out.add((m, path))
    return out


# ---------------------------------------------------------------------------- callers
@dataclass(frozen=True)
class Caller:
    name: str
    kind: str  # "none" | "bad" | "bearer" | "session" | "session-no-csrf" | "session-wrong-csrf"
    role: str | None = None
    writes_only: bool = False


CALLERS = [
    Caller("anonymous", "none"),
    Caller("garbage-token", "bad"),
    Caller("unknown-token", "bad"),
    Caller("tampered-token", "bad"),
    Caller("basic-auth", "bad"),
    Caller("made-up-cookie", "bad"),
    *[Caller(f"bearer-{r}", "bearer", r) for r in ROLES],
    *[Caller(f"session-{r}", "session", r) for r in ROLES],
    Caller("session-admin-without-csrf", "session-no-csrf", "admin", writes_only=True),
    Caller("session-admin-with-another-sessions-csrf", "session-wrong-csrf", "admin", writes_only=True),
]


def _bad_headers(api, name: str) -> dict[str, str]:
    admin = api.tokens["admin"]
    return {
        "garbage-token": {"Authorization": "Bearer nonsense"},
        "unknown-token": {"Authorization": "Bearer st_0123456789abcdef_" + "x" * 43},
        # the admin token's public prefix with its secret's last character changed
        "tampered-token": {"Authorization": "Bearer " + admin[:-1] + ("A" if admin[-1] != "A" else "B")},
        "basic-auth": {"Authorization": "Basic YWRtaW46YWRtaW4="},
        "made-up-cookie": {"Cookie": f"{SESSION_COOKIE}=" + "y" * 43},
    }[name]


def login(api, role: str) -> tuple[str, str]:
    """A new panel session of ``role``: (cookie value, CSRF token)."""
    with httpx.Client(base_url=api.url, timeout=30.0) as c:
        r = c.post("/api/v1/session", json={"token": api.tokens[role]})
        assert r.status_code == 200, r.text
        return c.cookies[SESSION_COOKIE], r.json()["csrf_token"]


@pytest.fixture(scope="module")
def sessions(api) -> dict[str, tuple[str, str]]:
    """One panel session per role for the whole matrix (the station idle first, so the
    matrix's one command, pause, is refused for the state: 409)."""
    with api.client("admin") as c:
        wait_idle(c)
    return {role: login(api, role) for role in ROLES}


def _headers(api, sessions, caller: Caller, method: str, path: str) -> dict[str, str]:
    if caller.kind == "none":
        return {}
    if caller.kind == "bad":
        return _bad_headers(api, caller.name)
    if caller.kind == "bearer":
        return {"Authorization": f"Bearer {api.tokens[caller.role]}"}
    cookie, csrf = sessions[caller.role]
    if (method, path) == ("DELETE", "/api/v1/session"):
        # a session of its own: a logout that goes through must not end the shared one
        cookie, csrf = login(api, caller.role)
    headers = {"Cookie": f"{SESSION_COOKIE}={cookie}"}
    if caller.kind == "session" and method not in SAFE:
        headers[CSRF_HEADER] = csrf  # reads go without it: they need none
    elif caller.kind == "session-wrong-csrf":
        headers[CSRF_HEADER] = sessions["operator"][1]
    return headers


@pytest.fixture(scope="module")
def client(api):
    """One connection pool for the matrix; its cookie jar is emptied around every call,
    so a caller sends exactly the headers its cell gives it."""
    with httpx.Client(base_url=api.url, timeout=30.0, follow_redirects=False) as c:
        yield c


def _call(client: httpx.Client, method: str, probe: Probe, headers: dict[str, str]) -> int:
    client.cookies.clear()
    try:
        with client.stream(method, probe.url, headers=headers, **probe.kwargs) as r:
            return r.status_code  # streams (SSE, MJPEG) are closed unread
    finally:
        client.cookies.clear()


def _expected(policy, caller: Caller, method: str, path: str) -> str:
    """'open' (past the auth layer), '401' or '403'."""
    if policy == PUBLIC:
        return "open"
    if caller.kind in ("none", "bad"):
        return "401"
    if caller.kind in ("session-no-csrf", "session-wrong-csrf"):
        return "403"  # only writes get these callers
    return "open" if caller.role in policy else "403"


def _cells():
    for (method, path), policy in POLICY.items():
        for caller in CALLERS:
            if caller.writes_only and (method in SAFE or policy == PUBLIC):
                continue
            yield pytest.param(method, path, caller, id=f"{method} {path} as {caller.name}")


def test_the_policy_covers_exactly_the_apps_routes(api):
    routes = app_routes(api.app)
    assert routes, "no routes found in the app"
    missing = sorted(routes - set(POLICY))
    stale = sorted(set(POLICY) - routes)
    assert not missing, f"routes without an access policy (add them to POLICY): {missing}"
    assert not stale, f"policy entries for routes the app no longer has: {stale}"
    # every route with a path parameter has a concrete request to try
    templated = {k for k in routes if "{" in k[1]}
    assert templated <= set(PROBES), f"routes without a probe: {sorted(templated - set(PROBES))}"


def test_the_routes_are_found_the_way_the_app_dispatches_them(api):
    """The route listing is not a stale copy: a route added to a router after the app
    was made shows up (and without a policy entry it would fail the test above)."""
    from fastapi import APIRouter

    from api.app import create_app
    from api.settings import Settings

    app = create_app(Settings(data_dir=api.data_dir))  # never started: no lifespan
    extra = APIRouter(prefix="/api/v1")
    extra.add_api_route("/unlisted", lambda: {}, methods=["POST"])
    app.include_router(extra)
    assert ("POST", "/api/v1/unlisted") in app_routes(app)
    assert ("POST", "/api/v1/unlisted") not in POLICY


@pytest.mark.parametrize("method, path, caller", list(_cells()))
def test_access(api, client, sessions, method, path, caller):
    policy = POLICY[(method, path)]
    expected = _expected(policy, caller, method, path)
    for probe in PROBES.get((method, path), [Probe(path)]):
        status = _call(client, method, probe, _headers(api, sessions, caller, method, path))
        where = f"{method} {probe.url} as {caller.name}: {status}"
        if expected == "open":
            assert status not in (401, 403) and status < 500, where
            if method not in SAFE and policy != PUBLIC:
                assert status in WRITE_ANSWERS.get((method, path), REFUSED_FOR_CONTENT), where
        else:
            assert status == int(expected), f"{where}, expected {expected}"
