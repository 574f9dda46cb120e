"""Security properties of the API beyond who-may-call-what (test_access_matrix.py):
tokens at rest and their comparison, the panel's session cookie, upload limits, path
traversal, and secrets in logs. docs/security.md names the threat each one answers.

The tests run against a server of their own (module-scoped): they upload files and
change directories, which must not disturb the shared server's tests. Its data folder
is ``<tmp>/data``; ``<tmp>`` itself is "outside" and holds the sentinels.
"""

from __future__ import annotations

import hashlib
import hmac
import http.client
import json
import logging
import re
import secrets
import socket
import time
from importlib import resources
from pathlib import Path
from urllib.parse import quote

import httpx
import pytest

from api.sessions import CSRF_HEADER, SESSION_COOKIE
from tests.api.conftest import start_server, stop_server, wait_idle
from tests.dbtools import rows as db_rows

SENTINEL = "SENTINEL-" + secrets.token_hex(8)  # in files outside the data folder only


@pytest.fixture(scope="module")
def sec(tmp_path_factory):
    base = tmp_path_factory.mktemp("security")
    data = base / "data"
    data.mkdir()
    srv, server, thread = start_server(data)
    try:
        yield srv
    finally:
        stop_server(server, thread)


def _port(srv) -> int:
    return int(srv.url.rsplit(":", 1)[1])


def raw_request(srv, method: str, target: str, headers: dict[str, str] | None = None,
                body: bytes = b"", timeout: float = 30.0) -> tuple[int, bytes]:
    """One request with the target exactly as given (httpx would normalise ``..``)."""
    conn = http.client.HTTPConnection("127.0.0.1", _port(srv), timeout=timeout)
    try:
        conn.putrequest(method, target, skip_accept_encoding=True)
        for k, v in (headers or {}).items():
            conn.putheader(k, v)
        if body or method in ("POST", "PUT"):
            conn.putheader("Content-Length", str(len(body)))
        conn.endheaders(body or None)
        resp = conn.getresponse()
        return resp.status, resp.read()
    finally:
        conn.close()


def _read_status(sock: socket.socket) -> int:
    """The status of the response on ``sock`` (headers only)."""
    buf = b""
    while b"\r\n\r\n" not in buf:
        chunk = sock.recv(65536)
        if not chunk:
            raise AssertionError(f"connection closed before a response: {buf[:200]!r}")
        buf += chunk
    return int(buf.split(b" ", 2)[1])


def _tree(root: Path, skip: Path | None = None) -> dict[str, tuple[int, int]]:
    """Every file and folder under ``root`` (but ``skip``): size and mtime."""
    out = {}
    for p in root.rglob("*"):
        if skip is not None and (p == skip or skip in p.parents):
            continue
        st = p.stat()
        out[str(p.relative_to(root)) + ("/" if p.is_dir() else "")] = (st.st_size if p.is_file() else 0,
                                                                        st.st_mtime_ns)
    return out


def _data_files(srv) -> dict[str, tuple[int, int]]:
    """The data folder's files but the database (which reads may touch)."""
    return {k: v for k, v in _tree(srv.data_dir).items() if not k.startswith("station.db")}


def _bearer(srv, role: str = "admin") -> dict[str, str]:
    return {"Authorization": f"Bearer {srv.tokens[role]}"}


def _login(srv, token: str, **headers) -> httpx.Response:
    with httpx.Client(base_url=srv.url, timeout=30.0) as c:
        return c.post("/api/v1/session", json={"token": token}, headers=headers)


def _cookie_attrs(set_cookie: str) -> tuple[str, set[str]]:
    """(value, lower-case attribute names and name=value pairs) of one Set-Cookie."""
    first, *attrs = [a.strip() for a in set_cookie.split(";")]
    name, _, value = first.partition("=")
    assert name == SESSION_COOKIE, set_cookie
    return value, {a.lower() for a in attrs}


# ============================================================= tokens at rest, comparison
def test_token_create_stores_only_a_salted_slow_hash(sec):
    """`station token create` prints the token once; nothing on disk holds it, the
    row holds PBKDF2-SHA256(token, its own salt), and the token works."""
    from typer.testing import CliRunner

    from station.cli.token import token_app
    from station.store.tokens import PBKDF2_ITERATIONS

    result = CliRunner().invoke(token_app, ["create", "--role", "engineer", "--name", "cli engineer",
                                            "--data", str(sec.data_dir)])
    assert result.exit_code == 0, result.output
    token = result.stdout.strip().splitlines()[0]
    prefix, secret = token.split("_")[1], token.split("_", 2)[2]
    assert token.startswith("st_") and len(secret) >= 43  # 256 random bits
    assert token not in result.stderr
    # no file of the data folder (database, its WAL, anything else) holds the token
    for path in sec.data_dir.rglob("*"):
        if path.is_file():
            blob = path.read_bytes()
            assert token.encode() not in blob and secret.encode() not in blob, path
    ((salt, stored),) = db_rows(sec.data_dir, "SELECT salt, token_hash FROM api_token WHERE prefix = :p", p=prefix)
    assert len(bytes.fromhex(salt)) >= 16 and PBKDF2_ITERATIONS >= 10_000
    assert stored == hashlib.pbkdf2_hmac("sha256", token.encode(), bytes.fromhex(salt), PBKDF2_ITERATIONS).hex()
    with httpx.Client(base_url=sec.url, headers={"Authorization": f"Bearer {token}"}) as c:
        assert c.get("/api/v1/session").json()["name"] == "cli engineer"


@pytest.fixture
def compare_spy(monkeypatch):
    """Every call of hmac.compare_digest / secrets.compare_digest (the server runs in
    this process), answered by the real function."""
    calls = []
    real = hmac.compare_digest

    def spy(a, b):
        calls.append((a, b))
        return real(a, b)

    monkeypatch.setattr(hmac, "compare_digest", spy)
    monkeypatch.setattr(secrets, "compare_digest", spy)
    return calls


def test_tokens_are_compared_in_constant_time(sec, compare_spy):
    from station.store.tokens import TokenRepository

    record, token = TokenRepository(sec.runtime.store).create("mes", name="timing")
    ((stored,),) = db_rows(sec.data_dir, "SELECT token_hash FROM api_token WHERE id = :i", i=record.id)
    with httpx.Client(base_url=sec.url) as c:
        # the right token: its hash is compared with the stored one by compare_digest
        assert c.get("/api/v1/station", headers={"Authorization": f"Bearer {token}"}).status_code == 200
        assert any(stored in (a, b) and a == b for a, b in compare_spy), "the token's hash was not compared " \
            "with hmac.compare_digest"
        compare_spy.clear()
        # its prefix with another secret: found by the prefix, refused by compare_digest
        forged = token[:len("st_") + 16 + 1] + "A" * 43
        assert c.get("/api/v1/station", headers={"Authorization": f"Bearer {forged}"}).status_code == 401
        assert any(stored in (a, b) and a != b for a, b in compare_spy), "a wrong token was not refused " \
            "by hmac.compare_digest"


def test_the_csrf_token_is_compared_in_constant_time(sec, compare_spy):
    r = _login(sec, sec.tokens["operator"])
    cookie, csrf = r.cookies[SESSION_COOKIE], r.json()["csrf_token"]
    with httpx.Client(base_url=sec.url, headers=_bearer(sec)) as admin:
        wait_idle(admin)
    compare_spy.clear()
    with httpx.Client(base_url=sec.url) as c:
        r = c.post("/api/v1/station/pause", headers={"Cookie": f"{SESSION_COOKIE}={cookie}", CSRF_HEADER: csrf})
        assert r.status_code == 409  # admitted, refused for the state: nothing ran
        assert any(csrf.encode() in (a, b) for a, b in compare_spy), "the CSRF token was not compared " \
            "with hmac.compare_digest"


def test_job_orders_and_commands_name_who_gave_them(sec):
    """Repudiation: the audit log says which token ordered an inspection, the command
    log which one commanded the station (one short inspection, aborted)."""
    from tests.api.conftest import PART, wait_done

    with httpx.Client(base_url=sec.url, headers=_bearer(sec, "mes"), timeout=30) as mes, \
            httpx.Client(base_url=sec.url, headers=_bearer(sec, "operator"), timeout=30) as operator:
        wait_idle(mes)
        r = mes.post("/api/v1/job-orders", json={"part_number": PART, "serial": "WHO-1", "order_id": "PO-7"})
        assert r.status_code == 202, r.text
        iid = r.json()["id"]
        # abort it once the engine runs the plan (the order is answered when the record
        # exists, a moment before; the inspection itself takes seconds)
        deadline = time.monotonic() + 10
        while (r := operator.post("/api/v1/station/abort")).status_code == 409 and time.monotonic() < deadline:
            time.sleep(0.02)
        assert r.status_code == 200, r.text
        assert wait_done(mes, iid)["state"] == "aborted"
        wait_idle(mes)
    audit = [e.message for e in sec.runtime.store.events(kind="audit", limit=1000, newest_first=True)]
    assert any(m.startswith("test mes (token ") and f"ordered inspection {iid}" in m and "'WHO-1'" in m
               and "'PO-7'" in m for m in audit), audit[:5]
    commands = [e.message for e in sec.runtime.store.events(kind="command", limit=1000, newest_first=True)]
    assert any(m.startswith("abort by test operator (token ") for m in commands), commands[:5]


# ============================================================= the panel's session cookie
def test_the_session_cookie_is_httponly_samesite_strict_and_kept_hashed(sec):
    r = _login(sec, sec.tokens["operator"])
    assert r.status_code == 200, r.text
    value, attrs = _cookie_attrs(r.headers["set-cookie"])
    assert "httponly" in attrs and "samesite=strict" in attrs and "path=/" in attrs
    assert "secure" not in attrs  # plain http on 127.0.0.1, cookie_secure off (the default)
    assert len(value) >= 43  # 256 random bits
    assert r.json()["csrf_token"] not in r.headers["set-cookie"]
    assert r.headers["cache-control"] == "no-store"
    # the server keeps the cookie's SHA-256, never the cookie
    kept = repr(vars(sec.runtime.sessions))
    assert value not in kept and hashlib.sha256(value.encode()).hexdigest() in kept


def test_cookie_secure_setting_marks_the_cookie_secure(sec, monkeypatch):
    from api.settings import Settings

    assert Settings().cookie_secure is False  # plain-http local use by default
    monkeypatch.setattr(sec.runtime.settings, "cookie_secure", True)
    r = _login(sec, sec.tokens["operator"])
    value, attrs = _cookie_attrs(r.headers["set-cookie"])
    assert "secure" in attrs and "httponly" in attrs and "samesite=strict" in attrs
    # logging out clears it with the same attributes (a browser matches them)
    headers = {"Cookie": f"{SESSION_COOKIE}={value}", CSRF_HEADER: r.json()["csrf_token"]}
    with httpx.Client(base_url=sec.url) as c:
        out = c.delete("/api/v1/session", headers=headers)
    assert out.status_code == 200
    _, attrs = _cookie_attrs(out.headers["set-cookie"])
    assert "secure" in attrs and "max-age=0" in attrs


def test_https_through_a_trusted_proxy_marks_the_cookie_secure(sec):
    """A TLS-terminating proxy on the same host says https in X-Forwarded-Proto
    (uvicorn trusts 127.0.0.1's forwarding headers by default)."""
    r = _login(sec, sec.tokens["operator"], **{"X-Forwarded-Proto": "https"})
    assert r.status_code == 200, r.text
    _, attrs = _cookie_attrs(r.headers["set-cookie"])
    assert "secure" in attrs


def test_station_serve_has_a_cookie_secure_option(monkeypatch):
    import typer
    import uvicorn
    from typer.testing import CliRunner

    import api.app
    from station.cli import serve

    seen = []
    monkeypatch.setattr(api.app, "create_app", lambda settings: seen.append(settings) or object())
    monkeypatch.setattr(uvicorn, "run", lambda *a, **kw: None)
    app = typer.Typer()
    serve.register(app)
    for args, want in (([], False), (["--cookie-secure"], True)):
        result = CliRunner().invoke(app, args)
        assert result.exit_code == 0, result.output
        assert seen[-1].cookie_secure is want


# ============================================================= upload limits
LIMIT = 1024 * 1024  # api.settings.MAX_UPLOAD_BYTES (the server's settings are the default)
SLACK = 64 * 1024  # multipart framing allowed on top of the file (api/app.py)

#: every route that takes a request body, as requested, and its kind
BODY_ROUTES = {
    ("POST", "/api/v1/models"): "multipart",
    ("POST", "/api/v1/calibrations"): "multipart",
    ("POST", "/api/v1/reports/iso230"): "multipart",
    ("POST", "/api/v1/reports/discovery"): "multipart",
    ("PUT", "/api/v1/parts/{part_number}"): "json",
    ("POST", "/api/v1/job-orders"): "json",
    ("POST", "/api/v1/session"): "json",
    ("POST", "/api/v1/checks"): "json",
    ("POST", "/api/v1/model-proposals/{proposal_id}/approve"): "json",
    ("POST", "/api/v1/model-proposals/{proposal_id}/reject"): "json",
    ("POST", "/api/v1/tokens/rotate"): "json",
    ("POST", "/api/v1/calibrations/master"): "json",
}
#: every file field of every upload
FILE_FIELDS = [("/api/v1/models", "file"), ("/api/v1/calibrations", "file"),
               ("/api/v1/reports/iso230", "recording"),
               ("/api/v1/reports/discovery", "model"), ("/api/v1/reports/discovery", "recording")]

ISO_CSV = ("# axis: Z\n# kind: linear\ntime_s,run,direction,target,deviation\n"
           "0,1,+1,0,1.0\n1,1,+1,10,2.0\n2,1,+1,20,3.0\n3,1,-1,20,1.0\n4,1,-1,10,0.0\n5,1,-1,0,-1.0\n"
           "6,2,+1,0,2.0\n7,2,+1,10,4.0\n8,2,+1,20,3.0\n9,2,-1,20,2.0\n10,2,-1,10,1.0\n11,2,-1,0,0.0\n")
AXIS_MODEL = ('[axis]\nname = "Z"\nkind = "linear"\n\n[baseline]\n'
              'target = [0.0, 20.0, 40.0, 60.0, 80.0, 100.0, 120.0]\n'
              'deviation = [0.0, 3.1, 6.0, 9.2, 12.1, 15.3, 18.0]\n\n[noise]\nsigma = 0.5\n')


def _station_model() -> str:
    return resources.files("station").joinpath("data/default_station.toml").read_text()


def _calibration() -> str:
    return json.dumps({"camera_matrix": [[1000.0, 0, 640], [0, 1000.0, 512], [0, 0, 1]],
                       "dist_coeffs": [0.0, 0.0, 0.0, 0.0], "image_size": [1280, 1024], "rms_px": 0.1})


def _valid_files(url: str) -> dict[str, tuple[str, str]]:
    """A valid upload for each upload route (the field under test is replaced)."""
    if url == "/api/v1/models":
        return {"file": ("model.toml", _station_model())}
    if url == "/api/v1/calibrations":
        return {"file": ("cal.json", _calibration())}
    if url == "/api/v1/reports/iso230":
        return {"recording": ("rec.csv", ISO_CSV)}
    from station.discovery.synth import Campaign, linear_model, make_recording
    from station.effects import Backlash

    rec = make_recording(linear_model(), (Backlash(4.0),), Campaign(seed=3)).to_csv()
    return {"model": ("z.toml", AXIS_MODEL), "recording": ("z.csv", rec)}


def _audit_count(srv) -> int:
    return len(srv.runtime.store.events(kind="audit", limit=1000))


def test_every_route_with_a_body_is_listed(sec):
    """A new upload (or any body) route must be added to BODY_ROUTES and its file
    fields to FILE_FIELDS: the lists are checked against the app's schema."""
    spec = sec.app.openapi()
    with_body = {(m.upper(), p): op["requestBody"]["content"]
                 for p, methods in spec["paths"].items() for m, op in methods.items() if "requestBody" in op}
    assert set(with_body) == set(BODY_ROUTES)
    declared = set()
    for (_m, p), content in with_body.items():
        if "multipart/form-data" not in content:
            continue
        schema = content["multipart/form-data"]["schema"]
        if "$ref" in schema:
            schema = spec["components"]["schemas"][schema["$ref"].rsplit("/", 1)[1]]
        for name, prop in schema["properties"].items():
            if prop.get("format") == "binary" or "contentMediaType" in prop:
                declared.add((p, name))
    assert declared == set(FILE_FIELDS)


def _concrete(path: str) -> str:
    return path.replace("{part_number}", "LIMIT-1").replace("{proposal_id}", "0123456789ab")


@pytest.mark.parametrize("method, path", list(BODY_ROUTES), ids=[f"{m} {p}" for m, p in BODY_ROUTES])
def test_a_declared_body_over_the_limit_is_refused_unread(sec, method, path):
    """Content-Length above the limit: 413 at once, before a byte of the body is sent."""
    before, audits = _data_files(sec), _audit_count(sec)
    with socket.create_connection(("127.0.0.1", _port(sec)), timeout=10) as sock:
        sock.sendall((f"{method} {_concrete(path)} HTTP/1.1\r\nHost: 127.0.0.1\r\n"
                      f"Authorization: Bearer {sec.tokens['admin']}\r\n"
                      f"Content-Type: application/json\r\nContent-Length: {LIMIT + SLACK + 1}\r\n\r\n").encode())
        assert _read_status(sock) == 413  # no body sent: the server did not wait for it
    assert _data_files(sec) == before and _audit_count(sec) == audits


@pytest.mark.parametrize("method, path", list(BODY_ROUTES), ids=[f"{m} {p}" for m, p in BODY_ROUTES])
def test_a_chunked_body_over_the_limit_is_refused_while_it_streams(sec, method, path):
    """No Content-Length (chunked): counted as it arrives, 413 once past the limit; the
    client has not even finished sending."""
    before, audits = _data_files(sec), _audit_count(sec)
    if BODY_ROUTES[(method, path)] == "multipart":
        ctype = "multipart/form-data; boundary=xyzzy"
        head = b'--xyzzy\r\nContent-Disposition: form-data; name="file"; filename="big.txt"\r\n\r\n'
    else:
        ctype, head = "application/json", b'{"token": "'
    with socket.create_connection(("127.0.0.1", _port(sec)), timeout=10) as sock:
        sock.sendall((f"{method} {_concrete(path)} HTTP/1.1\r\nHost: 127.0.0.1\r\n"
                      f"Authorization: Bearer {sec.tokens['admin']}\r\n"
                      f"Content-Type: {ctype}\r\nTransfer-Encoding: chunked\r\n\r\n").encode())
        sent, chunk = 0, b"#" * 16384
        for data in [head] + [chunk] * ((LIMIT + SLACK) // len(chunk) + 4):
            sock.sendall(b"%x\r\n%s\r\n" % (len(data), data))
            sent += len(data)
        assert sent > LIMIT + SLACK
        # the body is not finished (no last chunk): only the limit can end the request
        assert _read_status(sock) == 413
    assert _data_files(sec) == before and _audit_count(sec) == audits


@pytest.mark.parametrize("url, field", FILE_FIELDS, ids=[f"{u} {f}" for u, f in FILE_FIELDS])
def test_a_file_over_the_limit_is_refused_and_nothing_is_kept(sec, url, field):
    """A file of limit + 1 bytes in a body the middleware lets through: the route's own
    read refuses it (413), and nothing is written to the data folder."""
    files = _valid_files(url)
    name, _text = files[field]
    files[field] = (name, "#" * (LIMIT + 1))
    before, audits = _data_files(sec), _audit_count(sec)
    with httpx.Client(base_url=sec.url, headers=_bearer(sec), timeout=30) as c:
        r = c.post(url, files=files)
    assert r.status_code == 413, r.text
    assert _data_files(sec) == before and _audit_count(sec) == audits


def test_a_file_at_the_limit_is_accepted(sec):
    """The limit is the file's size: exactly the limit is fine (a model padded with a
    comment), so the 413s above are about size, not about the route."""
    text = _station_model()
    text += "#" * (LIMIT - len(text.encode()) - 1) + "\n"
    assert len(text.encode()) == LIMIT
    with httpx.Client(base_url=sec.url, headers=_bearer(sec, "engineer"), timeout=30) as c:
        r = c.post("/api/v1/models", files={"file": ("padded.toml", text)})
    assert r.status_code == 201, r.text
    assert r.json()["size"] == LIMIT


# ============================================================= path traversal
@pytest.fixture
def outside(sec, monkeypatch) -> Path:
    """The folder around the data folder, made the working directory (relative paths
    resolve there), with a sentinel file and a valid part spec whose "part number"
    is a file name: neither may ever be read through the API."""
    base = sec.data_dir.parent
    (base / "sentinel.txt").write_text(SENTINEL + "\n")
    spec = resources.files("station").joinpath("data/parts/ZDZG-22.2-12.3851.toml").read_text()
    spec = spec.replace('part_number = "ZDZG-22.2-12.3851"', 'part_number = "SPY-1.toml"')
    spec = spec.replace('description = "', f'description = "{SENTINEL} ')
    (base / "SPY-1.toml").write_text(spec)
    monkeypatch.chdir(base)
    return base


def _outside_state(base: Path, data_dir: Path) -> dict:
    return _tree(base, skip=data_dir)


def _check_data_dir_names(data_dir: Path) -> None:
    """Whatever the API wrote in the data folder has a name of its own making."""
    for p in data_dir.rglob("*"):
        assert ".." not in p.name and "\x00" not in p.name and "\\" not in p.name and "SPY" not in p.name, p
    parts = data_dir / "parts"
    if parts.is_dir():
        from api.routes.parts import is_plain_part_number

        for p in parts.iterdir():
            assert p.suffix == ".toml" and is_plain_part_number(p.stem), p


def _abs(p: Path) -> str:
    return quote(str(p), safe="")


#: what goes into a path parameter, as sent on the wire (percent-encoding kept)
def _payloads(base: Path) -> list[str]:
    return [
        "../../sentinel.txt", "..%2F..%2Fsentinel.txt", "..%2f..%2fsentinel.txt", "%2e%2e%2f%2e%2e%2fsentinel.txt",
        "..%252F..%252Fsentinel.txt", "..%5C..%5Csentinel.txt", "..", "%2e%2e", "...",
        _abs(base / "sentinel.txt"), _abs(base / "SPY-1.toml"), "sentinel.txt", "SPY-1.toml",
        "sentinel.txt%00", "SPY-1.toml%00.x", "%00",
    ]


#: every route with a path parameter; the test below checks the list is complete
TRAVERSAL_ROUTES = [
    ("GET", "/api/v1/inspections/{inspection_id}"),
    ("GET", "/api/v1/inspections/{inspection_id}/qif"),
    ("GET", "/api/v1/inspections/{inspection_id}/surface.png"),
    ("GET", "/api/v1/parts/{part_number}"),
    ("PUT", "/api/v1/parts/{part_number}"),
    ("POST", "/api/v1/models/{version}/activate"),
    ("POST", "/api/v1/calibrations/{version}/activate"),
    ("GET", "/api/v1/reports/discovery/{report_id}"),
    ("GET", "/api/v1/reports/discovery/{report_id}/plots/{name}"),
    ("POST", "/api/v1/station/{command}"),
    ("GET", "/api/v1/checks/{check_id}"),
    ("GET", "/api/v1/calibrations/master/{run_id}"),
    ("GET", "/api/v1/model-proposals/{proposal_id}"),
    ("GET", "/api/v1/model-proposals/{proposal_id}/plot"),
    ("POST", "/api/v1/model-proposals/{proposal_id}/approve"),
    ("POST", "/api/v1/model-proposals/{proposal_id}/reject"),
]
#: a plausible value for each path parameter of a route with several, while another one
#: carries the payload
PLAIN_PARAMS = {"{report_id}": "00000000-0000-4000-8000-000000000000", "{name}": "residual_position.png"}


def test_every_path_parameter_is_tried(sec):
    from tests.api.test_access_matrix import app_routes

    assert {r for r in app_routes(sec.app) if "{" in r[1]} == set(TRAVERSAL_ROUTES)


def _spec_body(part_number: str) -> bytes:
    """A valid part spec as JSON, named as the URL names it (so a PUT that got
    through would write it)."""
    from station.parts import load_part

    body = load_part("ZDZG-22.2-12.3851").to_json()
    body["part_number"] = part_number
    return json.dumps(body).encode()


@pytest.mark.parametrize("method, route", TRAVERSAL_ROUTES, ids=[f"{m} {r}" for m, r in TRAVERSAL_ROUTES])
def test_path_parameters_never_reach_outside_the_data_folder(sec, outside, method, route):
    from urllib.parse import unquote

    from api.routes.parts import is_plain_part_number

    params = re.findall(r"\{[a-z_]+\}", route)
    before = _outside_state(outside, sec.data_dir)
    for param, payload in [(p, x) for p in params for x in _payloads(outside)]:
        target = route.replace(param, payload)
        for other in set(params) - {param}:
            target = target.replace(other, PLAIN_PARAMS[other])
        headers = {**_bearer(sec)}
        body = b""
        if method == "PUT":
            headers["Content-Type"] = "application/json"
            body = _spec_body(unquote(payload))
        status, text = raw_request(sec, method, target, headers, body)
        where = f"{method} {target}: {status} {text[:200]!r}"
        if 200 <= status < 300:
            # only a part spec named by a plain part number ("sentinel.txt" is one),
            # stored in and read from <data>/parts
            assert route.startswith("/api/v1/parts/") and is_plain_part_number(unquote(payload)), where
        else:
            assert 400 <= status < 500, where
        assert SENTINEL.encode() not in text, where
    assert _outside_state(outside, sec.data_dir) == before
    _check_data_dir_names(sec.data_dir)


def test_a_job_order_cannot_name_a_file_as_its_part(sec, outside):
    """The part number of a job order is a number, never a spec file read from the
    server's working directory (load_part reads "<x>.toml" as a path)."""
    with httpx.Client(base_url=sec.url, headers=_bearer(sec, "mes"), timeout=30) as c:
        wait_idle(c)
        for pn in ("SPY-1.toml", "SPY-1.toml\x00", "../sentinel.txt", str(outside / "SPY-1.toml"), "..", "a/../b"):
            r = c.post("/api/v1/job-orders", json={"part_number": pn, "serial": "TRAVERSAL"})
            assert r.status_code == 422, (pn, r.status_code, r.text)
            assert SENTINEL not in r.text
        assert not c.get("/api/v1/station").json()["busy"]  # nothing started
        assert c.get("/api/v1/inspections", params={"serial": "TRAVERSAL"}).json()["total"] == 0


def test_the_part_list_reads_only_the_data_folder(sec, outside):
    with httpx.Client(base_url=sec.url, headers=_bearer(sec), timeout=30) as c:
        r = c.get("/api/v1/parts")
    assert r.status_code == 200 and SENTINEL not in r.text


@pytest.mark.parametrize("target", [
    "/panel/../app.py", "/panel/%2e%2e/app.py", "/panel/..%2fapp.py", "/panel/..%2Fapp.py", "/panel/..%5capp.py",
    "/panel/js/../../app.py", "/panel/%2e%2e%2f%2e%2e%2fapi%2fapp.py", "/panel//etc/passwd",
    "/panel/{abs_sentinel}", "/panel/%2F{abs_sentinel_q}", "/panel/..%00/app.py", "/panel/../../../../../../etc/passwd",
    "/../sentinel.txt", "/%2e%2e/sentinel.txt",
])
def test_the_panels_static_files_stay_in_their_folder(sec, outside, target):
    sentinel = outside / "sentinel.txt"
    target = target.replace("{abs_sentinel}", str(sentinel).lstrip("/")).replace(
        "{abs_sentinel_q}", quote(str(sentinel).lstrip("/"), safe=""))
    status, text = raw_request(sec, "GET", target)
    assert 400 <= status < 500, (target, status, text[:200])
    assert SENTINEL.encode() not in text and b"def create_app" not in text and b"root:" not in text


FILENAMES = ["../../sentinel-upload.txt", "..%2F..%2Fenc-upload.txt", "..\\..\\win-upload.txt",
             "{abs}", "a\x00b.txt", "", "..", "/"]


@pytest.mark.parametrize("url", ["/api/v1/models", "/api/v1/calibrations", "/api/v1/reports/iso230",
                                 "/api/v1/reports/discovery"])
def test_upload_file_names_are_only_names(sec, outside, url):
    """A file's name is kept as text (the version's metadata, the report's), never
    used as a path: every upload lands under its own number or id in the data folder."""
    before = _outside_state(outside, sec.data_dir)
    files = _valid_files(url)
    names = [n.replace("{abs}", str(outside / "abs-upload.txt")) for n in FILENAMES]
    if url == "/api/v1/reports/discovery":
        names = names[:3]  # a discovery takes about a second: the kinds of traversal, once each
    with httpx.Client(base_url=sec.url, headers=_bearer(sec, "engineer"), timeout=60) as c:
        for name in names:
            sent = {field: (name, text) for field, (_n, text) in files.items()}
            r = c.post(url, files=sent)
            assert r.status_code in (200, 201) or 400 <= r.status_code < 500, (name, r.status_code, r.text)
            assert SENTINEL not in r.text
    assert _outside_state(outside, sec.data_dir) == before
    _check_data_dir_names(sec.data_dir)
    # <data>/models also holds the station's model proposals and the approved changes
    # (station.monitor.proposals.ProposalBook: proposals/<id>.json, approved.json), named by the station
    book = {"models": {"proposals", "approved.json"}, "calibrations": set()}
    for kind, ext in (("models", "toml"), ("calibrations", "json")):
        folder = sec.data_dir / kind
        if folder.is_dir():
            assert all(p.name == "index.json" or p.name in book[kind] or (p.stem.isdigit() and p.suffix == f".{ext}")
                       for p in folder.iterdir()), sorted(p.name for p in folder.iterdir())
            proposals = folder / "proposals"
            if kind == "models" and proposals.is_dir():
                # each proposal's JSON and its picture (ProposalBook.plot_path)
                assert all(p.suffix in (".json", ".png") and p.stem.isalnum() for p in proposals.iterdir()), \
                    sorted(p.name for p in proposals.iterdir())
    reports = sec.data_dir / "reports" / "discovery"
    if reports.is_dir():
        import uuid

        from api.routes.reports import PLOT_VIEWS

        for p in reports.iterdir():
            if p.is_dir():  # a report's pictures: named by the report's id, each by the name the plots module gives it
                assert str(uuid.UUID(p.name)) == p.name and (reports / f"{p.name}.json").is_file(), p
                assert {q.name for q in p.iterdir()} <= set(PLOT_VIEWS), sorted(q.name for q in p.iterdir())
            else:
                assert p.suffix == ".json" and str(uuid.UUID(p.stem)) == p.stem, p


# ============================================================= secrets never logged
def test_secrets_never_reach_a_log_or_the_store(sec, caplog):
    """Create a token with `station token create`, log in to the panel with it, use it
    as a Bearer token (also, wrongly, in a query string), mistype one: with every
    logger at DEBUG (SQLAlchemy's statements and parameters included) and uvicorn's
    access log on, no log record, no event of the store and no file of the data folder
    holds the token, its secret, the session cookie, the CSRF token or the mistyped
    token."""
    from typer.testing import CliRunner

    from station.cli.token import token_app

    # every logger at DEBUG: the root, and each one that sets a level of its own
    # (SQLAlchemy's WARN, uvicorn's); those that do not propagate (uvicorn's access
    # log) get the capturing handler themselves
    caplog.set_level(logging.DEBUG)
    own_handler = []
    for name, logger in list(logging.root.manager.loggerDict.items()):
        if not isinstance(logger, logging.Logger):
            continue
        if logger.level != logging.NOTSET:
            caplog.set_level(logging.DEBUG, logger=name)
        if not logger.propagate:
            logger.addHandler(caplog.handler)
            own_handler.append(logger)
    assert logging.getLogger("uvicorn.access") in own_handler
    try:
        result = CliRunner().invoke(token_app, ["create", "--role", "operator", "--name", "log check",
                                                "--data", str(sec.data_dir)])
        assert result.exit_code == 0, result.output
        token = result.stdout.strip().splitlines()[0]
        mistyped = token[:-2] + ("zz" if not token.endswith("zz") else "yy")
        with httpx.Client(base_url=sec.url, timeout=30) as c:
            # the panel: a failed login, a login, reads and a write with the cookie, logout
            assert c.post("/api/v1/session", json={"token": mistyped}).status_code == 401
            r = c.post("/api/v1/session", json={"token": token})
            assert r.status_code == 200
            cookie, csrf = c.cookies[SESSION_COOKIE], r.json()["csrf_token"]
            assert c.get("/api/v1/station").status_code == 200
            wait_idle(c)
            assert c.post("/api/v1/station/pause", headers={CSRF_HEADER: csrf}).status_code == 409
            assert c.post("/api/v1/station/pause").status_code == 403  # no CSRF token
            assert c.delete("/api/v1/session", headers={CSRF_HEADER: csrf}).status_code == 200
            c.cookies.clear()
            # the token as a Bearer token: reads, a refused write, a wrong one
            bearer = {"Authorization": f"Bearer {token}"}
            assert c.get("/api/v1/inspections", params={"limit": 1}, headers=bearer).status_code == 200
            assert c.put("/api/v1/parts/LOG-1", json={"part_number": "LOG-1"}, headers=bearer).status_code == 403
            assert c.get("/api/v1/station", headers={"Authorization": f"Bearer {mistyped}"}).status_code == 401
            # a client that puts its token into the URL: refused, and not logged either
            for query in ({"token": token}, {"access_token": token}, {"x": token}):
                assert c.get("/api/v1/station", params=query).status_code == 401
    finally:
        for logger in own_handler:
            logger.removeHandler(caplog.handler)
    # the test's own HTTP client (httpx, httpcore) logs the URLs it requests: that is
    # this test's doing (a token put into a query string on purpose), not the server's
    records = [r for r in caplog.records if not r.name.startswith(("httpx", "httpcore"))]
    access_lines = [r.getMessage() for r in records if r.name == "uvicorn.access"]
    # the capture works: the requests above are in the access log (and their targets)
    assert sum("/api/v1/station" in line for line in access_lines) >= 5, access_lines
    assert any("limit=1" in line for line in access_lines)
    assert any(r.name.startswith("sqlalchemy.engine") for r in records)  # SQL at DEBUG: parameters too
    logged = "\n".join(f"{r.name} {r.getMessage()} {r.exc_text or ''} {r.args!r}" for r in records)
    events = "\n".join(f"{e.kind} {e.message}" for e in sec.runtime.store.events(limit=1000))
    assert any("logged in to the panel" in e.message for e in sec.runtime.store.events(kind="audit", limit=1000))
    secret_part = token.split("_", 2)[2]
    secrets_ = {"token": token, "token secret": secret_part, "session cookie": cookie, "CSRF token": csrf,
                "mistyped token": mistyped, "mistyped secret": mistyped.split("_", 2)[2]}
    files = {str(p): p.read_bytes() for p in sec.data_dir.rglob("*") if p.is_file()}
    for what, value in secrets_.items():
        assert value not in logged, f"the {what} is in the log"
        assert value not in events, f"the {what} is in the store's event log"
        assert value not in result.stderr, f"the {what} is on stderr"
        for path, blob in files.items():
            assert value.encode() not in blob, f"the {what} is in {path}"


def test_access_log_targets_are_redacted():
    from api.logsafe import redact_target

    tok = "st_0123456789abcdef_" + "s" * 43
    assert redact_target("/api/v1/inspections?limit=5&serial=A1") == "/api/v1/inspections?limit=5&serial=A1"
    out = redact_target(f"/api/v1/station?token={tok}&access_token=x&api%5Fkey=y&csrf=z&limit=2&q={tok}")
    assert tok not in out and "s" * 43 not in out and "=x" not in out and "=y" not in out and "=z" not in out
    assert "limit=2" in out and "st_0123456789abcdef_" in out  # the public prefix stays: it names the token
    assert "s" * 43 not in redact_target(f"/api/v1/inspections/{tok}")
