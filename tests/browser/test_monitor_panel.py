"""The panel's face of the station's watch (docs/api.md, "Station needs a check"): the
banner over every page while the station needs a check, its "Check on master" button,
and the engineer's model proposals page.

The served station's world has its calibration block knocked 8 um along Z before the
first part (sim.drift.Collision): only the master sees it, so a check on the master is
out of control, the station needs a check and proposes the block's installation error;
the engineer approves it in the panel, and the check the banner's button starts is in
control again.
"""

from __future__ import annotations

import re

from playwright.sync_api import expect

from tests.browser.conftest import INSPECTION_TIMEOUT_MS, check_master_over_rest, login, open_page, screenshot


def test_the_banner_asks_for_a_check_and_the_engineer_approves_the_proposal(browser, knocked_station):
    st = knocked_station
    with open_page(browser, st.url) as eng:
        login(eng, st.tokens["engineer"])
        banner = eng.locator("#check-banner")
        expect(banner).to_be_hidden()
        expect(eng.locator("#tab-proposals")).to_be_visible()

        # a check out of control (the knock): the banner appears on its own (SSE)
        check = check_master_over_rest(st)
        assert check["in_control"] is False and check["proposal_id"], check
        expect(banner).to_be_visible()
        expect(eng.locator("#check-text")).to_have_text(re.compile(r"^Station needs a check: master check"))
        bg = banner.evaluate("b => getComputedStyle(b).backgroundColor")
        assert bg == "rgb(242, 194, 0)", bg  # the panel's attention colour (amber)
        expect(eng.locator("#check-master")).to_be_visible()
        expect(eng.locator("#proposal-badge")).to_have_text("1")
        # on every page: the results page too
        eng.click("nav.tabs button[data-view=results]")
        expect(banner).to_be_visible()

        # the operator sees the banner and its button, not the proposals; the MES neither button nor proposals
        for role, button in (("operator", True), ("mes", False)):
            with open_page(browser, st.url) as other:
                login(other, st.tokens[role])
                expect(other.locator("#check-banner")).to_be_visible()
                expect(other.locator("#check-text")).to_contain_text("Station needs a check")
                expect(other.locator("#check-master")).to_be_visible() if button else \
                    expect(other.locator("#check-master")).to_be_hidden()
                expect(other.locator("#tab-proposals")).to_be_hidden()
                assert not other.problems, (role, other.problems)

        # the engineer's proposals page: reason, change, expected change per hole, evidence
        eng.click("nav.tabs button[data-view=proposals]")
        card = eng.locator(f".proposal[data-id='{check['proposal_id']}']")
        expect(card).to_have_count(1)
        expect(card.locator(".proposal-state")).to_have_text("PROPOSED")
        expect(card.locator(".proposal-reason")).to_contain_text("master check")
        change = card.locator("table.changes tbody tr")
        expect(change).to_have_count(1)
        expect(change.locator("td").nth(0)).to_have_text("installation.J.z_um")
        expect(change.locator("td").nth(1)).to_have_text(re.compile(r"^\+[789]\.\d{3} um$"))
        expect(change.locator("td").nth(2)).to_contain_text("calibration block")
        expected = card.locator("table.expected tbody tr")
        expect(expected).to_have_count(2)
        expect(expected.nth(0).locator("td").nth(1)).to_have_text(re.compile(r"^-[789]\.\d\d$"))
        expect(card.locator("table.evidence tbody tr")).to_have_count(2)
        version_before = eng.locator("#model-version").inner_text()
        screenshot(eng, "model-proposal")

        # approve with a note: the card shows who and when, and the station's model changed
        card.locator("input.note").fill("block re-seated")
        card.locator("button.approve").click()
        expect(card.locator(".proposal-state")).to_have_text("APPROVED")
        expect(card.locator(".decision")).to_have_text(re.compile(r"^APPROVED by Test Engineer at .+: block re-seated$"))
        expect(card.locator("button")).to_have_count(0)
        expect(eng.locator("#model-version")).not_to_have_text(version_before)
        expect(eng.locator("#proposal-badge")).to_be_hidden()
        with st.client("mes") as c:
            listed = c.get("/api/v1/model-proposals").json()
        assert listed["items"][-1]["state"] == "approved" and listed["items"][-1]["decided_by"] == "Test Engineer"
        assert listed["model_version"] in eng.locator("#model-version").inner_text()
        screenshot(eng, "model-proposal-approved")

        # the banner's button: a check with the approved model is in control, and the banner goes
        eng.click("nav.tabs button[data-view=operation]")
        expect(eng.locator("#check-master")).to_be_enabled(timeout=INSPECTION_TIMEOUT_MS)
        eng.click("#check-master")
        expect(banner).to_be_hidden(timeout=INSPECTION_TIMEOUT_MS)
        expect(eng.locator("#job-message")).to_contain_text("in control", timeout=INSPECTION_TIMEOUT_MS)
        with st.client("mes") as c:
            status = c.get("/api/v1/station").json()
        assert status["needs_check"] is False
        screenshot(eng, "check-in-control")
        assert not eng.problems, eng.problems
