"""Response headers: the panel may not be framed and runs only its own scripts; no
response is sniffed as another type; streams keep their headers too."""

from __future__ import annotations


def test_panel_pages_carry_the_policy_and_api_answers_are_not_sniffed(api):
    with api.client(None) as c:
        page = c.get("/panel/")
        assert page.status_code == 200
        assert page.headers["x-frame-options"] == "DENY"
        assert "frame-ancestors 'none'" in page.headers["content-security-policy"]
        assert "script-src 'self'" in page.headers["content-security-policy"]
        assert page.headers["referrer-policy"] == "same-origin"
        assert page.headers["cache-control"] == "no-cache"  # the static files' own value replaced
        assert page.headers["x-content-type-options"] == "nosniff"
        health = c.get("/healthz")
        assert health.headers["x-content-type-options"] == "nosniff"
        assert "content-security-policy" not in health.headers  # the panel's policy only
        assert len(health.headers.get_list("x-content-type-options")) == 1
    with api.client("operator") as c:
        r = c.get("/api/v1/station")
        assert r.status_code == 200 and r.headers["x-content-type-options"] == "nosniff"
