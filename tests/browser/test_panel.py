"""The operator panel in a real browser: log in, start inspections, see PASS and FAIL,
the results table, the plots and the discovery reports page; log out."""

from __future__ import annotations

import re

from playwright.sync_api import expect

from tests.browser.conftest import INSPECTION_TIMEOUT_MS, login, screenshot

PART = "ZDZG-22.2-12.3851"
#: the standard part with a diameter tolerance the holes (about 0.70 mm) miss
FAIL_PART = "PANEL-FAIL-1"


def _start(page, part: str, serial: str, order: str = "") -> None:
    page.select_option("#part", part)
    page.fill("#serial", serial)
    page.fill("#order", order)
    expect(page.locator("#start")).to_be_enabled(timeout=INSPECTION_TIMEOUT_MS)
    page.click("#start")


def test_an_unknown_token_is_refused_and_the_panel_needs_a_login(page, station):
    page.goto("/panel/", wait_until="domcontentloaded")
    page.wait_for_url("**/panel/login.html")
    page.fill("#token", "st_0123456789abcdef_" + "x" * 43)
    page.click("#login-button")
    expect(page.locator("#login-message")).to_contain_text("not valid")
    screenshot(page, "login-refused")


def test_operator_inspects_a_good_part_and_sees_pass(page, station):
    login(page, station.tokens["operator"])
    expect(page.locator("#user-name")).to_have_text("Test Operator")
    expect(page.locator("#link")).to_have_text("live")
    expect(page.locator("#estop")).to_have_text("released")
    _start(page, PART, "SN-PANEL-PASS", "ORD-7")
    # progress: the sequencer's steps arrive over SSE
    expect(page.locator("#progress-count")).to_contain_text(re.compile(r"step \d+ of \d+"),
                                                            timeout=INSPECTION_TIMEOUT_MS)
    expect(page.locator("#verdict")).to_have_text(re.compile("PASS"), timeout=INSPECTION_TIMEOUT_MS)
    expect(page.locator("#part-info")).to_contain_text("SN-PANEL-PASS")
    expect(page.locator("#chars tbody tr")).to_have_count(4)
    expect(page.locator("#chars tbody tr.fail")).to_have_count(0)
    first = page.locator("#recent tbody tr").first
    expect(first).to_contain_text("SN-PANEL-PASS")
    expect(first).to_contain_text("PASS")
    expect(page.locator("#state")).to_have_text(re.compile("IDLE|READY"))
    expect(page.locator("#z-pos")).to_have_text(re.compile(r"\d"))
    expect(page.locator("#progress-text")).to_contain_text("ready for the next part")
    expect(page.locator("#start")).to_be_enabled()
    screenshot(page, "inspection-pass")
    assert not page.problems, page.problems


def test_a_part_out_of_tolerance_shows_fail(page, station):
    with station.client("engineer") as c:
        spec = c.get(f"/api/v1/parts/{PART}").json()
        spec["part_number"] = FAIL_PART
        spec["description"] = "standard part, diameter limits 0.80..0.90 (the holes miss them)"
        for hole in spec["holes"]:
            hole["diameter"] = {"nominal": 0.7, "upper": 0.2, "lower": 0.1}
        r = c.put(f"/api/v1/parts/{FAIL_PART}", json=spec)
        assert r.status_code == 200, r.text
    login(page, station.tokens["operator"])
    page.reload(wait_until="domcontentloaded")  # the part list now has the new spec
    expect(page.locator("#part option", has_text=FAIL_PART)).to_have_count(1)
    _start(page, FAIL_PART, "SN-PANEL-FAIL")
    expect(page.locator("#verdict")).to_have_text(re.compile("FAIL"), timeout=INSPECTION_TIMEOUT_MS)
    expect(page.locator("#verdict")).to_have_class(re.compile(r"\bfail\b"))
    expect(page.locator("#chars tbody tr.fail")).to_have_count(2)  # both diameters
    first = page.locator("#recent tbody tr").first
    expect(first).to_contain_text("SN-PANEL-FAIL")
    expect(first.locator("td.res-fail")).to_have_text("FAIL")
    expect(page.locator("#progress-text")).to_contain_text("ready for the next part")
    screenshot(page, "inspection-fail")
    # the results page lists it and shows its characteristics
    page.click("nav.tabs button[data-view=results]")
    page.select_option("#filter-result", "fail")
    page.click("#filter-apply")
    row = page.locator("#results tbody tr", has_text="SN-PANEL-FAIL")
    expect(row).to_have_count(1)
    row.click()
    expect(page.locator("#result-detail .verdict")).to_have_text("FAIL")
    screenshot(page, "results-fail")
    assert not page.problems, page.problems


def test_axis_error_plots_and_discovery_reports(page, station):
    from station.discovery.synth import Campaign, linear_model, make_recording
    from station.effects import Backlash

    rec = make_recording(linear_model(), (Backlash(4.0),), Campaign(seed=3))
    model_toml = ('[axis]\nname = "Z"\nkind = "linear"\n\n[baseline]\ntarget = [0.0, 60.0, 120.0]\n'
                  'deviation = [0.0, 9.2, 18.0]\n\n[noise]\nsigma = 0.5\n')
    with station.client("engineer") as c:
        r = c.post("/api/v1/reports/discovery", files={"model": ("z-axis.toml", model_toml),
                                                        "recording": ("z-run.csv", rec.to_csv())})
        assert r.status_code == 200, r.text
    login(page, station.tokens["operator"])
    page.click("nav.tabs button[data-view=errors]")
    expect(page.locator("#plot-z-lin path")).not_to_have_count(0)
    expect(page.locator("#model-name")).to_contain_text("Active model")
    screenshot(page, "axis-errors")
    page.click("nav.tabs button[data-view=discovery]")
    row = page.locator("#discovery tbody tr", has_text="Test Engineer")
    expect(row.first).to_contain_text("backlash")
    row.first.click()
    expect(page.locator("#discovery-detail")).to_contain_text("backlash")
    screenshot(page, "discovery-reports")
    assert not page.problems, page.problems


def test_logout_ends_the_session(page, station):
    login(page, station.tokens["operator"])
    page.click("#logout")
    page.wait_for_url("**/panel/login.html")
    r = page.request.get("/api/v1/station")
    assert r.status == 401
    page.goto("/panel/", wait_until="domcontentloaded")
    page.wait_for_url("**/panel/login.html")
