"""The per-token limit on writes (api/ratelimit.py), on the shared test server with
the default settings (issue 22: "a flood of writes gets 429").

A flood of writes from one token is admitted up to the burst, then refused with 429,
``Retry-After`` (whole seconds) and a detail naming the limit; after waiting that long
a write is admitted again. Another token is not affected, and the flooding token still
reads. A panel session counts against the token it was opened with. Requests without
a valid token are refused (401) before they count. A rotation does not buy a fresh
burst. Each test floods with tokens of its own, so the other tests' tokens keep
their buckets.
"""

from __future__ import annotations

import math
import time

import httpx
import pytest

from api.sessions import CSRF_HEADER
from station.store.tokens import TokenRepository

#: a write the mes and operator roles are admitted to, refused for its content (422):
#: nothing changes on the station however often it is sent
ORDER = {"part_number": "NO-SUCH-PART", "serial": "FLOOD"}
ADMITTED = 422


def _token(api, role: str, name: str) -> str:
    return TokenRepository(api.runtime.store).create(role, name=name)[1]


def _client(api, token: str | None = None) -> httpx.Client:
    headers = {"Authorization": f"Bearer {token}"} if token else {}
    return httpx.Client(base_url=api.url, headers=headers, timeout=30.0)


def _flood(c: httpx.Client, limit: int = 1000, **kw) -> tuple[int, httpx.Response, float]:
    """Write back to back until refused: (writes admitted, the refusal, seconds taken)."""
    start = time.monotonic()
    for admitted in range(limit):
        r = c.post("/api/v1/job-orders", json=ORDER, **kw)
        if r.status_code != ADMITTED:
            return admitted, r, time.monotonic() - start
    raise AssertionError(f"{limit} writes in a row were all admitted")


def test_a_flood_of_writes_gets_429_with_retry_after_and_others_are_unaffected(api):
    limiter = api.runtime.write_limiter
    rate, burst = limiter.rate_per_s, limiter.burst
    assert rate > 0, "the test server runs with the default limit"
    with _client(api, _token(api, "mes", "flooding MES")) as flooder, \
            _client(api, _token(api, "mes", "well-behaved MES")) as other:
        admitted, refused, took_s = _flood(flooder)
        assert refused.status_code == 429, refused.text
        # the burst, and what the rate refilled while the flood ran
        assert burst <= admitted <= burst + rate * took_s + 1
        retry = refused.headers["retry-after"]
        assert retry.isdigit() and 1 <= int(retry) <= math.ceil(1 / rate)
        detail = refused.json()["detail"]
        assert "too many writes" in detail and f"{rate:g} writes/s" in detail and f"bursts of up to {burst}" in detail
        # another token writes; the flooding one still reads
        assert other.post("/api/v1/job-orders", json=ORDER).status_code == ADMITTED
        assert all(flooder.get("/api/v1/station").status_code == 200 for _ in range(3 * burst))
        # after Retry-After a write is admitted again
        time.sleep(int(retry))
        assert flooder.post("/api/v1/job-orders", json=ORDER).status_code == ADMITTED


def test_a_panel_session_counts_against_its_token(api):
    token = _token(api, "operator", "operator, flooding")
    with _client(api, token) as bearer:
        _admitted, refused, _ = _flood(bearer)
        assert refused.status_code == 429
    start = time.monotonic()
    with _client(api) as browser:
        r = browser.post("/api/v1/session", json={"token": token})  # the login itself is not a counted write
        assert r.status_code == 200, r.text
        admitted, refused, took_s = _flood(browser, headers={CSRF_HEADER: r.json()["csrf_token"]})
    assert refused.status_code == 429 and "retry-after" in refused.headers
    # what refilled since the Bearer flood, not a session's own burst
    limiter = api.runtime.write_limiter
    assert admitted <= limiter.rate_per_s * (time.monotonic() - start + 1.0) < limiter.burst, (admitted, took_s)


@pytest.mark.parametrize("headers", [
    {}, {"Authorization": "Bearer nonsense"}, {"Authorization": "Bearer st_0123456789abcdef_" + "x" * 43},
    {"Cookie": "station_session=" + "y" * 43},
], ids=["anonymous", "garbage", "unknown", "made-up-cookie"])
def test_unauthenticated_writes_are_refused_before_they_count(api, headers):
    buckets = len(api.runtime.write_limiter)
    with _client(api) as c:
        codes = {c.post("/api/v1/job-orders", json=ORDER, headers=headers).status_code
                 for _ in range(2 * api.runtime.write_limiter.burst)}
    assert codes == {401}
    assert len(api.runtime.write_limiter) <= buckets  # no bucket for a caller that is nobody


def test_a_rotation_does_not_buy_a_fresh_burst(api):
    with _client(api, _token(api, "mes", "MES rotating out of a flood")) as c:
        _admitted, refused, _ = _flood(c)
        assert refused.status_code == 429
        time.sleep(int(refused.headers["retry-after"]))  # a few writes' worth back: one is the rotation
        r = c.post("/api/v1/tokens/rotate", json={"grace_s": 0})
        assert r.status_code == 200, r.text
        new = r.json()["token"]
    with _client(api, new) as c:
        admitted, refused, took_s = _flood(c)
    # what was left and what refilled, not a fresh burst
    limiter = api.runtime.write_limiter
    assert refused.status_code == 429
    assert admitted <= limiter.rate_per_s * (int(refused.headers["retry-after"]) + took_s + 1.0) < limiter.burst


def test_station_serve_sets_the_limit(monkeypatch):
    import typer
    import uvicorn
    from typer.testing import CliRunner

    import api.app
    from api.settings import Settings
    from station.cli import serve

    seen = []
    monkeypatch.setattr(api.app, "create_app", lambda settings: seen.append(settings) or object())
    monkeypatch.setattr(uvicorn, "run", lambda *a, **kw: None)
    app = typer.Typer()
    serve.register(app)
    for args, want in (([], (Settings.write_rate_per_s, Settings.write_burst)),
                       (["--write-rate", "0.5", "--write-burst", "10"], (0.5, 10)),
                       (["--write-rate", "0"], (0.0, Settings.write_burst))):
        result = CliRunner().invoke(app, args)
        assert result.exit_code == 0, result.output
        assert (seen[-1].write_rate_per_s, seen[-1].write_burst) == want
    for args, says in ((["--write-rate", "-1"], "--write-rate"), (["--write-rate", "nan"], "--write-rate"),
                       (["--write-burst", "0"], "--write-burst")):
        result = CliRunner().invoke(app, args)
        assert result.exit_code == 2 and says in result.stderr, result.output
