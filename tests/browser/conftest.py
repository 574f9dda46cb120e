"""Browser tests of the operator panel: Playwright for Python driving Debian's
Chromium (/usr/bin/chromium; `make test` installs it with apt-get when missing).

The station runs as `station serve` in a subprocess on 127.0.0.1 (a free port), on
simulated hardware 50x faster than real time, with a temporary data folder; tokens
are made beforehand with the store API, as `station token create` does.

A missing Chromium FAILS these tests (it does not skip them): a skipped browser test
would hide a machine that cannot run them.
"""

from __future__ import annotations

import contextlib
import os
import re
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Iterator

import httpx
import pytest
from playwright.sync_api import expect

CHROMIUM = "/usr/bin/chromium"
#: the machine's closed network refuses Chromium's background connections: none are made
CHROMIUM_ARGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
                 "--disable-background-networking", "--disable-component-update", "--disable-sync"]
TIME_SCALE = 50
ROLES = ("operator", "engineer", "mes")
#: screenshots for people to look at (gitignored)
ARTIFACTS = Path(__file__).resolve().parents[2] / "test-artifacts" / "browser"
#: longest an inspection may take here before the test counts it as hung (not a timing assertion)
INSPECTION_TIMEOUT_MS = 180_000


@dataclass
class Station:
    url: str
    data_dir: Path
    tokens: dict[str, str]

    def client(self, role: str) -> httpx.Client:
        return httpx.Client(base_url=self.url, headers={"Authorization": f"Bearer {self.tokens[role]}"},
                            timeout=30.0)


@contextlib.contextmanager
def serve_station(data: Path, extra: list[str] | None = None) -> Iterator[Station]:
    """`station serve` on simulated hardware with its data in ``data`` (``extra``: more
    arguments, e.g. ``--scenario F``), with a token of every role; stopped on exit."""
    from station.bench import served
    from station.store import Store
    from station.store.tokens import TokenRepository

    with Store(data_dir=data) as store:
        repo = TokenRepository(store)
        tokens = {role: repo.create(role, name=f"Test {role.title()}")[1] for role in ROLES}
    server = served.start(data, time_scale=TIME_SCALE, extra=list(extra or []), ready_timeout_s=90)
    try:
        yield Station(server.url, data, tokens)
    finally:
        served.stop(server.proc)


# module scope, not session: Playwright's sync API keeps an event loop running in the
# main thread while it is open, and every later test that calls asyncio.run would fail
@pytest.fixture(scope="module")
def station(tmp_path_factory) -> Station:
    with serve_station(tmp_path_factory.mktemp("panel-data")) as st:
        yield st


@pytest.fixture(scope="module")
def browser():
    if not os.path.exists(CHROMIUM):
        pytest.fail(f"{CHROMIUM} is missing: install Debian's chromium (apt-get install -y chromium; "
                    "`make test` does this)", pytrace=False)
    from playwright.sync_api import sync_playwright

    with sync_playwright() as p:
        b = p.chromium.launch(executable_path=CHROMIUM, headless=True, args=CHROMIUM_ARGS)
        try:
            yield b
        finally:
            b.close()


@contextlib.contextmanager
def open_page(browser, url: str):
    """A page in a fresh browser context on ``url``; ``page.problems`` collects page
    errors and console errors."""
    context = browser.new_context(base_url=url, viewport={"width": 1600, "height": 1000})
    pg = context.new_page()
    pg.set_default_timeout(30_000)
    problems: list[str] = []
    pg.on("pageerror", lambda exc: problems.append(f"page error: {exc}"))
    # the login page asks whether a session exists: its 401 is the expected answer; and
    # Chromium asks each new origin for /favicon.ico, which the panel does not have
    pg.on("console", lambda msg: problems.append(f"console {msg.type}: {msg.text}")
          if msg.type == "error" and "status of 401" not in msg.text
          and not msg.location.get("url", "").endswith("/favicon.ico") else None)
    pg.problems = problems
    try:
        yield pg
    finally:
        context.close()


@pytest.fixture
def page(browser, station):
    with open_page(browser, station.url) as pg:
        yield pg


def login(page, token: str) -> None:
    page.goto("/panel/login.html", wait_until="domcontentloaded")
    page.fill("#token", token)
    page.click("#login-button")
    page.wait_for_selector("#view-operation:not(.hidden)")
    expect(page.locator("#user-name")).to_have_text(re.compile(r"\w"))


def screenshot(page, name: str) -> Path:
    ARTIFACTS.mkdir(parents=True, exist_ok=True)
    path = ARTIFACTS / f"{name}.png"
    page.screenshot(path=str(path), full_page=True)
    print(f"screenshot: {path}")
    return path



#: a world whose calibration block was knocked 8 um along the bore at power-on
KNOCK = '\n[world.collision]\nat_s = 0.0\nbody = "J"\nshift = { z_um = 8.0 }\n'


@pytest.fixture(scope="module")
def knocked_station(tmp_path_factory) -> Station:
    """A served station on the default scenario with a knocked datum (one per module)."""
    data = tmp_path_factory.mktemp("panel-knocked")
    scenario = data / "knocked.toml"
    scenario.write_text((Path(__file__).resolve().parents[2] / "sim" / "scenarios" / "default.toml").read_text()
                        + KNOCK)
    with serve_station(data, ["--scenario", str(scenario)]) as st:
        yield st


def check_master_over_rest(station: Station) -> dict:
    """A check on the master as the operator's REST client starts it, polled to its end."""
    with station.client("operator") as client:
        r = client.post("/api/v1/checks", json={"kind": "master"})
        assert r.status_code == 202, r.text
        deadline = time.monotonic() + INSPECTION_TIMEOUT_MS / 1000
        while True:
            body = client.get(f"/api/v1/checks/{r.json()['id']}").json()
            if body["state"] != "running":
                return body
            assert time.monotonic() < deadline, "the check did not end"
            time.sleep(0.2)
