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
