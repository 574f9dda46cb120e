"""The operator panel in a real browser: log in, start inspections, see PASS and FAIL
with the scan's findings and the machine time, the results table, the plots and the
discovery reports page; log out."""

from __future__ import annotations

import re
from pathlib import Path

import pytest
from playwright.sync_api import expect

from tests.browser.conftest import INSPECTION_TIMEOUT_MS, login, open_page, screenshot, serve_station

REPO = Path(__file__).resolve().parents[2]
PART = "ZDZG-22.2-12.3851"
#: the machine time line: "machine time 7.1 s", then ", 1.09 x the plan's lower bound"
#: when the plan's lower bound is known, then "(modelled)" under a twin
MACHINE_TIME = re.compile(r"^machine time \d+\.\d s(, \d+\.\d\d x the plan's lower bound)? \(modelled\)$")
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
    # the scan's findings: the standard part's angular datum, set by hole_1; nothing abnormal
    findings = page.locator("#part-extras ul.findings li")
    expect(findings).to_have_count(1)
    datum = page.locator("#part-extras li.finding-datum")
    expect(datum).to_contain_text("angular datum")
    expect(datum).to_contain_text("set by hole_1")
    expect(datum.locator(".finding-kind")).to_have_text("datum")
    expect(datum.locator(".finding-where")).to_contain_text(re.compile(r"axial 71\.0\d\d mm, angle .* deg"))
    expect(page.locator("#part-extras li.warning")).to_have_count(0)
    expect(page.locator("#part-extras h2")).to_have_text("Findings")
    expect(page.locator("#part-extras .cycle")).to_have_text(MACHINE_TIME)
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


def test_the_machine_time_line_says_how_far_from_the_plans_lower_bound(page, station):
    """The results page's detail of an inspection whose cycle has a lower bound (the
    record as the API answers it, with the cycle of docs/api.md's example)."""
    cycle = {"machine_s": 7.1, "basis": "modelled", "lower_bound_s": 6.5, "ratio": 1.0923,
             "breakdown": {"moves_s": 3.0, "settle_s": 1.0, "frames_s": 2.0, "vision_s": 1.0, "other_s": 0.1},
             "lower_bound_breakdown": {"moves_s": 3.0, "settle_s": 1.0, "frames_s": 2.5, "vision_s": 0.0,
                                       "other_s": 0.0}}

    def with_cycle(route):
        body = route.fetch().json()
        body.update(machine_s=7.1, cycle=cycle)
        route.fulfill(json=body)

    login(page, station.tokens["operator"])
    page.route(re.compile(r".*/api/v1/inspections/[0-9a-f-]{36}$"), with_cycle)
    page.click("nav.tabs button[data-view=results]")
    page.click("#filter-apply")
    page.locator("#results tbody tr").first.click()
    line = page.locator("#result-detail .cycle")
    expect(line).to_have_text("machine time 7.1 s, 1.09 x the plan's lower bound (modelled)")
    expect(line).to_have_attribute("title", re.compile(r"moves 3\.00 s, settle 1\.00 s.*\nlower bound 6\.5 s"))
    assert not page.problems, page.problems


@pytest.fixture(scope="module")
def stray_station(tmp_path_factory):
    """A station whose part lacks hole_2 and has a stray drilling 2.5 mm beside hole_1
    (the world of tests/e2e/test_identity.py)."""
    data = tmp_path_factory.mktemp("panel-stray")
    head, _, _ = (REPO / "sim" / "scenarios" / "default.toml").read_text().partition("[[world.holes]]")
    holes = [("hole_1", 71.05, 20.0, 0.70), ("stray", 73.55, 24.0, 0.80)]
    scenario = data / "stray.toml"
    scenario.write_text(head + "".join(
        f'[[world.holes]]\nname = "{n}"\naxial_mm = {a}\nangle_deg = {c}\ndiameter_mm = {d}\n\n' for n, a, c, d in holes))
    with serve_station(data, ["--scenario", str(scenario)]) as st:
        yield st


def test_an_unexpected_hole_is_a_warning_among_the_findings(browser, stray_station):
    with open_page(browser, stray_station.url) as page:
        login(page, stray_station.tokens["operator"])
        _start(page, PART, "SN-PANEL-STRAY")
        expect(page.locator("#verdict")).to_have_text(re.compile("FAIL"), timeout=INSPECTION_TIMEOUT_MS)
        expect(page.locator("#progress-text")).to_contain_text("ready for the next part")
        warning = page.locator("#part-extras ul.findings li.warning")
        expect(warning).to_have_count(1)
        expect(warning).to_have_class(re.compile(r"\bfinding-unexpected_hole\b"))
        expect(warning.locator(".finding-kind")).to_have_text("WARNING: unexpected hole")
        expect(warning).to_contain_text(re.compile(r"^WARNING: unexpected hole unexpected hole of 0\.\d{3} mm at 73\.5"))
        expect(warning.locator(".finding-where")).to_contain_text(re.compile(r"axial 73\.5\d\d mm, angle 2[34]\.\d\d deg"))
        expect(page.locator("#part-extras li.finding-datum")).to_contain_text("set by hole_1")
        expect(page.locator("#part-extras .cycle")).to_have_text(MACHINE_TIME)
        # the warning's colour is the panel's attention colour, not the plain row's
        bg = warning.evaluate("li => getComputedStyle(li).backgroundColor")
        plain = page.locator("#part-extras li.finding-datum").evaluate("li => getComputedStyle(li).backgroundColor")
        assert bg == "rgb(242, 194, 0)" and plain != bg, (bg, plain)
        screenshot(page, "inspection-unexpected-hole")
        # the results page's detail shows the same findings
        page.click("nav.tabs button[data-view=results]")
        page.click("#filter-apply")
        page.locator("#results tbody tr", has_text="SN-PANEL-STRAY").click()
        expect(page.locator("#result-detail li.warning")).to_contain_text("nearest spec hole hole_1")
        expect(page.locator("#result-detail ul.findings li")).to_have_count(2)
        screenshot(page, "results-unexpected-hole")
        assert not page.problems, page.problems


def test_the_results_page_filters_by_station(page, station):
    """Another station writes the same database (docs/plant.md): the results page lists
    both stations' records with a Station column, its Station filter shows one station's,
    and the operation page's recent parts are this station's own."""
    from station.store import Store

    with Store(data_dir=station.data_dir, station_id="line2-st1") as other:  # as that station's store writes
        iid = other.begin_inspection(PART, serial="SN-OTHER-STATION")
        other.finish(iid, "aborted", reason="aborted on line 2")
    login(page, station.tokens["operator"])
    expect(page.locator("#recent tbody tr", has_text="SN-OTHER-STATION")).to_have_count(0)
    page.click("nav.tabs button[data-view=results]")
    options = page.locator("#filter-station option")
    expect(options).to_contain_text(["all", "line2-st1", "station (this station)"])
    rows = page.locator("#results tbody tr")
    expect(rows.filter(has_text="SN-OTHER-STATION")).to_have_count(1)
    page.select_option("#filter-station", "line2-st1")
    page.click("#filter-apply")
    expect(rows).to_have_count(1)
    expect(rows.first.locator("td").nth(1)).to_have_text("line2-st1")
    rows.first.click()
    expect(page.locator("#result-detail .part-info")).to_contain_text("station line2-st1")
    page.select_option("#filter-station", "station")
    page.click("#filter-apply")
    expect(rows.filter(has_text="SN-OTHER-STATION")).to_have_count(0)
    expect(rows.first.locator("td").nth(1)).to_have_text("station")
    screenshot(page, "results-by-station")
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
    # the report's own findings list (the same list helper as an inspection's findings)
    expect(page.locator("#discovery-detail h2.list-title", has_text="Findings")).to_have_count(1)
    expect(page.locator("#discovery-detail ul").first).to_contain_text("between approach directions")
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
