"""The console says what a run achieved (issue 46 item 2): a run whose charging was refused reads
"completed with issues: charging refused" on its page, in the history (not a success) and in its
report, with the same words; the fleet card shows no mission item on the parked UAV."""

from __future__ import annotations

import re

import pytest

from tests.conftest import Tenant
from tests.console.browser import open_page, shot, sign_in
from tests.e2e.harness import FINAL, platform
from tests.polling import eventually

pytestmark = pytest.mark.slow  # a browser and the whole platform: not in the fast lane

WORDS = "completed with issues: charging refused"


async def test_a_run_whose_charging_was_refused_reads_completed_with_issues_everywhere(
    live_server, tenant: Tenant, tmp_path, browser
):
    from playwright.async_api import expect

    async with platform(live_server.url, tenant, tmp_path) as p:
        run_id = await p.start_run()
        await p.wait_state(run_id, ("flying",), 60)
        await eventually(lambda: (p.agent.autopilot.state.alt_rel or 0) > 10, 60, "the climb")
        p.world.base.charger.fault = True
        body = await p.wait_state(run_id, FINAL, 150)
        assert body["outcome"] == "completed_with_issues", (body["reason"], body["timeline"])

        page, traffic = await open_page(browser, live_server.url + "/")
        await sign_in(page, tenant.emails["viewer"], Tenant.PASSWORD)
        # the fleet card of the parked UAV: its autopilot still holds the last mission's item
        uav_card = page.get_by_role("region", name=re.compile("^UAV "))
        await expect(uav_card).to_contain_text("– (on the ground)", timeout=30_000)
        assert not re.search(r"Mission item\s*\d+ of \d+", await uav_card.inner_text())

        await page.goto(f"{live_server.url}/#/runs/{run_id}")
        detail = page.get_by_role("region", name=re.compile("^Run of"))
        await expect(detail).to_contain_text(WORDS)
        await expect(detail.get_by_text("completed with issues", exact=True)).to_be_visible()
        charging = page.get_by_role("list", name="Steps of the run").get_by_role("listitem").last
        await expect(charging).to_contain_text("Starting to charge ⚠ charging refused")
        await shot(page, "run-completed-with-issues")

        await page.get_by_role("link", name="History").click()
        past = page.get_by_role("table", name=re.compile("Past runs"))
        await expect(past).to_contain_text(WORDS)
        summary = page.get_by_role("region", name=re.compile("^Fleet summary"))
        await expect(summary).to_contain_text("1Completed with issues")
        await expect(summary).to_contain_text("0 %Success rate")
        by = page.get_by_role("list", name="Runs not completed, by outcome and cause")
        await expect(by).to_have_text("completed with issues: charging refused 1")
        await shot(page, "history-outcomes")

        await past.get_by_role("link", name=re.compile("^Report of the run")).click()
        await expect(page.get_by_role("heading", name="Run report")).to_be_visible()
        await expect(page.locator("main")).to_contain_text(f"{WORDS}. ")
        await shot(page, "report-outcomes")
        assert traffic.errors == []
        await page.context.close()


@pytest.mark.realtime  # a landing loop through the camera (tests/priority.py)
async def test_the_reports_landing_plot_ends_on_the_touchdown_its_headline_gives(
    live_server, tenant: Tenant, tmp_path, browser
):
    """A precision landing (camera + IR) measures its touchdown offset: the report's headline
    gives it, and the distance-from-the-pad plot ends on that same figure (it used to end on the
    last GNSS sample, metres away when the base's survey or the fix was off)."""
    from playwright.async_api import expect

    async with platform(live_server.url, tenant, tmp_path, speed=2.0, precland={}) as p:
        run_id = await p.start_run()
        body = await p.wait_state(run_id, FINAL, 240)
        assert body["outcome"] == "completed", (body["reason"], body["timeline"])
        report = (
            await p.api.get(f"/api/v1/runs/{run_id}/report", headers=p.tenant.h("viewer"))
        ).json()
        error_m = report["landing_error_m"]
        assert error_m is not None, report["landing"]

        page, traffic = await open_page(browser, live_server.url + "/")
        await sign_in(page, tenant.emails["viewer"], Tenant.PASSWORD)
        await page.goto(f"{live_server.url}/#/report/{run_id}")
        await expect(page.get_by_role("heading", name="Run report")).to_be_visible()
        headline = f"{error_m * 100:.1f} cm"
        await expect(page.locator(".figures")).to_contain_text(f"{headline}Landing error")
        plot = page.get_by_role("img", name=re.compile("^Landing error: "))
        await expect(plot).to_have_attribute(
            "aria-label",
            re.compile(rf"ending at {error_m:.2f} m$" if error_m else r"ending at 0 m$"),
        )
        caption = page.get_by_text(re.compile("^Horizontal distance from the pad"))
        await expect(caption).to_contain_text(f"the touchdown the agent measured, {headline}")
        await shot(page, "report-landing-plot")
        assert traffic.errors == []
        await page.context.close()
