"""A real API server for the tests: uvicorn on 127.0.0.1 (an OS-chosen port) in a
thread, with the simulated station (twins on 127.0.0.1) and a store in a temporary
folder; tokens of every role made beforehand through the store, as `station token
create` does."""

from __future__ import annotations

import socket
import threading
import time
from dataclasses import dataclass
from pathlib import Path

import httpx
import pytest
import uvicorn

from api.app import create_app
from api.settings import Settings
from station.store import Store
from station.store.tokens import TokenRepository

PART = "ZDZG-22.2-12.3851"
#: simulated moves 50x faster than real time: an inspection takes a few seconds
TIME_SCALE = 50.0
ROLES = ("mes", "operator", "engineer", "admin")
#: longest an inspection may take in a test before it counts as hung
INSPECTION_TIMEOUT_S = 120.0


@dataclass
class Server:
    url: str
    data_dir: Path
    tokens: dict[str, str]
    app: object

    def client(self, role: str | None = "admin", **kw) -> httpx.Client:
        headers = {"Authorization": f"Bearer {self.tokens[role]}"} if role else {}
        return httpx.Client(base_url=self.url, headers=headers, timeout=httpx.Timeout(30.0), **kw)

    @property
    def runtime(self):
        return self.app.state.runtime


def make_tokens(data_dir: Path) -> dict[str, str]:
    with Store(data_dir=data_dir) as store:
        repo = TokenRepository(store)
        return {role: repo.create(role, name=f"test {role}")[1] for role in ROLES}


def start_server(data_dir: Path, **settings) -> tuple[Server, uvicorn.Server, threading.Thread]:
    tokens = make_tokens(data_dir)
    app = create_app(Settings(data_dir=data_dir, time_scale=TIME_SCALE, sse_keepalive_s=1.0, **settings))
    # proto IPPROTO_TCP, not 0: asyncio sets TCP_NODELAY only on sockets that say they
    # are TCP; without it every response (headers, then body) waits ~40 ms on Nagle and
    # the client's delayed ACK
    sock = socket.socket(socket.AF_INET, socket.SOCK_STREAM, socket.IPPROTO_TCP)
    sock.bind(("127.0.0.1", 0))
    port = sock.getsockname()[1]
    server = uvicorn.Server(uvicorn.Config(app, log_level="warning", timeout_graceful_shutdown=3,
                                           lifespan="on"))
    thread = threading.Thread(target=server.run, kwargs={"sockets": [sock]}, daemon=True)
    thread.start()
    deadline = time.monotonic() + 60
    while not server.started:
        if not thread.is_alive() or time.monotonic() > deadline:
            raise RuntimeError("the API server did not start")
        time.sleep(0.05)
    return Server(f"http://127.0.0.1:{port}", data_dir, tokens, app), server, thread


def stop_server(server: uvicorn.Server, thread: threading.Thread) -> None:
    server.should_exit = True
    thread.join(timeout=30)
    assert not thread.is_alive(), "the API server did not stop"


@pytest.fixture(scope="session")
def api(tmp_path_factory) -> Server:
    srv, server, thread = start_server(tmp_path_factory.mktemp("api-data"))
    try:
        yield srv
    finally:
        stop_server(server, thread)


def wait_done(client: httpx.Client, inspection_id: str, timeout: float = INSPECTION_TIMEOUT_S) -> dict:
    """Poll a job until it is no longer running (as a MES would)."""
    deadline = time.monotonic() + timeout
    while True:
        r = client.get(f"/api/v1/inspections/{inspection_id}")
        r.raise_for_status()
        body = r.json()
        if body["state"] != "running":
            return body
        if time.monotonic() > deadline:
            raise AssertionError(f"inspection {inspection_id} still running after {timeout} s")
        time.sleep(0.2)


def wait_idle(client: httpx.Client, timeout: float = INSPECTION_TIMEOUT_S) -> None:
    deadline = time.monotonic() + timeout
    while client.get("/api/v1/station").json()["busy"]:
        if time.monotonic() > deadline:
            raise AssertionError("the station stayed busy")
        time.sleep(0.2)
