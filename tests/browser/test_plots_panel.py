"""The panel shows its pictures (issue 20, "show it"): a model proposal's before/after
picture on the proposals page, with its explanation and the expected change at each
hole, and a discovery run's residual plots before and after on the discovery page.

The served station's world has its calibration block knocked 8 um along Z (as in
test_monitor_panel.py): a check on the master over REST is out of control and the
station proposes the block's installation error, with the checks it rests on drawn.
"""

from __future__ import annotations

import re
import uuid
from datetime import datetime, timezone

from playwright.sync_api import TimeoutError as PlaywrightTimeout
from playwright.sync_api import expect

from tests.browser.conftest import check_master_over_rest, login, open_page, screenshot

#: an <img> that loaded a picture: complete, and decoded to a size
LOADED = "img => img.complete && img.naturalWidth > 0 && img.naturalHeight > 0"


#: ... and is laid out on the page wider than px (a loaded picture can still be 0 px
#: wide for a moment, until the browser lays the page out again: a loaded CI run saw it)
SHOWN = "([img, px]) => img.clientWidth > px"


def _wait_loaded(page, img, min_shown_px: int) -> dict:
    """Wait until the <img> has loaded its picture and is laid out wider than ``min_shown_px`` (at most
    30 s each); its natural size and its width on the page."""
    img.wait_for(state="visible")
    page.wait_for_function(LOADED, arg=img.element_handle(), timeout=30_000)
    try:
        page.wait_for_function(SHOWN, arg=[img.element_handle(), min_shown_px], timeout=30_000)
    except PlaywrightTimeout:
        pass  # the caller's assertion says what width it has
    return img.evaluate("img => ({w: img.naturalWidth, h: img.naturalHeight, shown: img.clientWidth})")


def test_the_proposals_page_shows_the_proposals_picture(browser, knocked_station):
    from station.monitor.proposals import Change, Proposal, ProposalBook

    st = knocked_station
    check = check_master_over_rest(st)
    assert check["in_control"] is False and check["proposal_id"], check
    pid = check["proposal_id"]
    with st.client("engineer") as c:
        listed = {p["id"]: p for p in c.get("/api/v1/model-proposals").json()["items"]}
    assert listed[pid]["plot_url"] == f"/api/v1/model-proposals/{pid}/plot", listed[pid]
    # and one without checks to show (a proposal written before proposals had pictures): no picture
    bare = Proposal(uuid.uuid4().hex[:12], datetime.now(timezone.utc).isoformat(), "v-old", "an older proposal",
                    [Change("installation.J.z_um", 1.5, why="older")], {"hole_1.position": [-1.5]},
                    {"hole_1": -1.5, "hole_2": -1.5})
    ProposalBook(st.data_dir).add(bare)
    assert not ProposalBook(st.data_dir).plot_path(bare.id).exists()

    with open_page(browser, st.url) as eng:
        login(eng, st.tokens["engineer"])
        eng.click("nav.tabs button[data-view=proposals]")
        card = eng.locator(f".proposal[data-id='{pid}']")
        expect(card).to_have_count(1)
        img = card.locator("figure.proposal-plot img")
        expect(img).to_have_count(1)
        expect(img).to_have_attribute("src", f"/api/v1/model-proposals/{pid}/plot")
        size = _wait_loaded(eng, img, 300)
        assert size["w"] > 500 and size["h"] > 200 and size["shown"] > 300, size
        expect(card.locator("figure.proposal-plot figcaption")).to_contain_text("before and after")
        # with its change, its explanation and the expected change at each hole
        expect(card.locator("table.changes tbody tr td").first).to_have_text("installation.J.z_um")
        kind = listed[pid]["explanation"].get("kind")
        assert kind, listed[pid]["explanation"]
        expect(card.locator(".proposal-explanation .explanation-kind")).to_have_text(kind.upper())
        description = listed[pid]["explanation"].get("description")
        if description:
            expect(card.locator(".proposal-explanation")).to_contain_text(description)
        expected = card.locator("table.expected tbody tr")
        expect(expected).to_have_count(len(listed[pid]["expected_change_um"]))
        expect(expected.nth(0).locator("td").nth(1)).to_have_text(re.compile(r"^[-+]\d+\.\d\d$"))
        # the proposal without a picture says so, with no broken image
        other = eng.locator(f".proposal[data-id='{bare.id}']")
        expect(other).to_have_count(1)
        expect(other.locator("img")).to_have_count(0)
        expect(other.locator(".no-plot")).to_contain_text("No picture")
        expect(eng.locator("figure.missing")).to_have_count(0)
        card.scroll_into_view_if_needed()
        screenshot(eng, "model-proposal-picture")
        assert not eng.problems, eng.problems


def test_the_discovery_page_shows_the_residual_before_and_after(browser, knocked_station):
    from station.discovery.synth import Campaign, linear_model, make_recording
    from station.effects import Backlash

    st = knocked_station
    rec = make_recording(linear_model(), (Backlash(4.0),), Campaign(seed=3))
    model_toml = ('[axis]\nname = "Z"\nkind = "linear"\n\n[baseline]\ntarget = [0.0, 60.0, 120.0]\n'
                  'deviation = [0.0, 9.2, 18.0]\n\n[noise]\nsigma = 0.5\n')
    with st.client("engineer") as c:
        r = c.post("/api/v1/reports/discovery", files={"model": ("z-plots.toml", model_toml),
                                                        "recording": ("z-plots.csv", rec.to_csv())})
        assert r.status_code == 200, r.text
        entry = c.get(r.headers["location"]).json()
    names = [p["name"] for p in entry["plots"]]
    assert {"residual_position.png", "residual_time.png", "residual_direction.png"} <= set(names), names

    with open_page(browser, st.url) as page:
        login(page, st.tokens["operator"])  # any role reads the reports and their pictures
        page.click("nav.tabs button[data-view=discovery]")
        # the station's only report (its row names who made it, not the files)
        page.locator("#discovery tbody tr", has_text="Test Engineer").first.click()
        detail = page.locator("#discovery-detail")
        expect(detail.locator("h2").first).to_contain_text("z-plots.toml + z-plots.csv")
        imgs = detail.locator("figure.picture img")
        expect(imgs).to_have_count(len(names))
        for i, name in enumerate(names):
            img = imgs.nth(i)
            expect(img).to_have_attribute("src", f"/api/v1/reports/discovery/{entry['id']}/plots/{name}")
            size = _wait_loaded(page, img, 200)
            assert size["w"] > 500 and size["h"] > 200 and size["shown"] > 200, (name, size)
        expect(detail.locator("figure.plot-residual_position figcaption")).to_contain_text("before and after")
        # next to its numbers: the verdict and the RMS before and after
        expect(detail.locator(".part-info")).to_contain_text(re.compile(r"RMS \d+\.\d\d before, \d+\.\d\d after"))
        expect(detail.locator("figure.missing")).to_have_count(0)
        screenshot(page, "discovery-plots")
        assert not page.problems, page.problems
