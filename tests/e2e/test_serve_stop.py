"""`station serve` stopped as systemd stops it (SIGTERM) after an inspection: a clean exit.

uvicorn re-raises the signal it shut down for; under the default handler the process
would die by SIGTERM with no exit handler run, and multiprocessing's resource tracker
would report the renderer's queues as "leaked semaphore objects". The server turns it
into an orderly exit with status 0.
"""

from __future__ import annotations

import subprocess
import time

import httpx
import pytest

from station.bench import served
from station.store import Store
from station.store.tokens import TokenRepository


@pytest.mark.timeout(240)
def test_sigterm_after_an_inspection_exits_zero_with_nothing_leaked(tmp_path):
    with Store(data_dir=tmp_path) as store:
        token = TokenRepository(store).create("mes", name="Test MES")[1]
    server = served.start(tmp_path, time_scale=50.0, ready_timeout_s=120)
    try:
        auth = {"Authorization": f"Bearer {token}"}
        r = httpx.post(f"{server.url}/api/v1/job-orders", timeout=10,
                       headers={**auth, "Idempotency-Key": "stop-test-1"},
                       json={"part_number": "ZDZG-22.2-12.3851", "serial": "SN-STOP"})
        assert r.status_code == 202, r.text
        link = r.json()["links"]["self"]
        deadline = time.monotonic() + 120
        while (state := httpx.get(f"{server.url}{link}", headers=auth, timeout=10).json()["state"]) == "running":
            assert time.monotonic() < deadline, "the inspection did not finish"
            time.sleep(0.2)
        # the inspection rendered its frames in the camera twin's renderer process
        assert state == "complete", server.log_tail
        server.proc.terminate()
        try:
            code = server.proc.wait(timeout=40)
        except subprocess.TimeoutExpired:
            pytest.fail(f"station serve did not stop within 40 s of SIGTERM: {server.log_tail}")
    finally:
        served.stop(server.proc)
    log = (tmp_path / "server.log").read_text(errors="replace")
    assert "Application shutdown complete" in log
    assert (code, "leaked semaphore" in log) == (0, False), log[-2000:]
