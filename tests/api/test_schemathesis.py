"""Property-based requests generated from the app's own OpenAPI schema (schemathesis
4.x): whatever a client sends, the API answers 2xx-4xx, never 5xx.

A server of its own (a fresh data folder), so the generated writes (part specs,
uploads, station commands) do not disturb the other tests; without the per-token
limit on writes (a fuzzer is a flood by design: 429s would hide the routes from it;
the limit is test_rate_limit.py's business). The live streams never
end by design and are tested in test_live.py. Examples are bounded to stay quick.
"""

from __future__ import annotations

import pytest
import schemathesis
from hypothesis import HealthCheck, given, settings

from tests.api.conftest import start_server, stop_server


@pytest.fixture(scope="module")
def fuzz_server(tmp_path_factory):
    srv, server, thread = start_server(tmp_path_factory.mktemp("fuzz-data"), write_rate_per_s=0)
    try:
        yield srv
    finally:
        stop_server(server, thread)


#: operations not fuzzed: endless streams (SSE, MJPEG); the token rotation, which would
#: swap the fuzzer's own token away (tested in test_token_expiry.py); a calibration run,
#: which holds the station for up to minutes (200 poses), so every later answer would
#: depend on whether it is still running (hypothesis then sees "inconsistent data
#: generation" when it replays a sequence); its bodies, 202, 409 and 422 are tested in
#: test_calibrate_master_route.py
EXCLUDED = ("/api/v1/events", "/api/v1/camera.mjpg", "/api/v1/tokens/rotate", "/api/v1/calibrations/master")


def test_no_server_errors(fuzz_server):
    schema = schemathesis.openapi.from_url(f"{fuzz_server.url}/openapi.json")
    headers = {"Authorization": f"Bearer {fuzz_server.tokens['admin']}"}  # roles are test_auth's business
    tested = []
    for result in schema.get_all_operations():
        operation = result.ok()
        if operation.path in EXCLUDED:
            continue

        @given(case=operation.as_strategy())
        @settings(max_examples=12, deadline=None, suppress_health_check=list(HealthCheck), derandomize=True,
                  database=None)
        def no_5xx(case):
            response = case.call(base_url=fuzz_server.url, headers=headers, timeout=60)
            assert response.status_code < 500, (f"{case.method} {case.formatted_path} -> {response.status_code}: "
                                                f"{response.text[:500]}")

        no_5xx()
        tested.append(f"{operation.method.upper()} {operation.path}")
    assert len(tested) >= 18, tested  # the schema's operations were found and exercised


def test_stateful_sequences_follow_the_links_without_server_errors(fuzz_server):
    """Sequences along the schema's OpenAPI links (api/openapi_links.py): a job order,
    then its inspection and QIF; an upload, then its activation; a part written, then
    read. Every response 2xx-4xx."""
    import time

    import httpx

    schema = schemathesis.openapi.from_url(f"{fuzz_server.url}/openapi.json")
    headers = {"Authorization": f"Bearer {fuzz_server.tokens['admin']}"}
    # one finished inspection, so the list's items lead to their records (an inferred link)
    with httpx.Client(base_url=fuzz_server.url, headers=headers, timeout=60) as c:
        for _ in range(600):
            r = c.post("/api/v1/job-orders", json={"part_number": "ZDZG-22.2-12.3851", "serial": "STATEFUL-1"})
            if r.status_code != 409:
                break
            time.sleep(0.1)  # a job started by the stateless fuzzing is still running
        assert r.status_code == 202, r.text
        while c.get(f"/api/v1/inspections/{r.json()['id']}").json()["state"] == "running":
            time.sleep(0.1)
    base = schema.exclude(path=["/api/v1/tokens/rotate", "/api/v1/calibrations/master"]).as_state_machine()
    followed: list[str] = []

    class Workflow(base):
        def before_call(self, case):
            case.headers = {**(case.headers or {}), **headers}

        def get_call_kwargs(self, case):
            return {"base_url": fuzz_server.url, "timeout": 60}

        def validate_response(self, response, case, additional_checks=None, **kwargs):
            assert response.status_code < 500, (f"{case.method} {case.formatted_path} -> {response.status_code}: "
                                                f"{response.text[:500]}")

        def after_call(self, response, case):
            followed.append(f"{case.method} {case.operation.path} {response.status_code}")

    link_rules = [name for name in dir(Workflow) if name.startswith(("POST_", "PUT_", "GET_"))]
    assert any(n.startswith("POST_api_v1_job_orders") and "GetInspection" in n for n in link_rules), link_rules
    Workflow.run(settings=settings(max_examples=15, stateful_step_count=4, deadline=None, derandomize=True,
                                   database=None, suppress_health_check=list(HealthCheck)))
    # a link was really followed: an inspection fetched by the id a job order returned
    assert any(f.startswith("GET /api/v1/inspections/{inspection_id} 200") for f in followed), followed[:40]
