"""Property-based requests generated from the app's own OpenAPI schema (schemathesis
4.x): whatever a client sends, the API answers 2xx-4xx, never 5xx.

A server of its own (a fresh data folder), so the generated writes (part specs,
uploads, station commands) do not disturb the other tests. The live streams never
end by design and are tested in test_live.py. Examples are bounded to stay quick.
"""

from __future__ import annotations

import pytest
import schemathesis
from hypothesis import HealthCheck, given, settings

from tests.api.conftest import start_server, stop_server


@pytest.fixture(scope="module")
def fuzz_server(tmp_path_factory):
    srv, server, thread = start_server(tmp_path_factory.mktemp("fuzz-data"))
    try:
        yield srv
    finally:
        stop_server(server, thread)


#: operations not fuzzed: endless streams (SSE, MJPEG)
EXCLUDED = ("/api/v1/events", "/api/v1/camera.mjpg")


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
