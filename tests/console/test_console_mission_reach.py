"""Issue 46 item 3 in Debian's Chromium: the QGroundControl fixture near Zurich imported against a
base in Porto. The mission page draws the base and the mission on one map (with the flights
there and back), says the mission is far away with its distance, and its check names the
distance and the UAV's reach."""

from __future__ import annotations

import asyncio

import pytest

from server.missions.geometry import haversine_m
from tests.conftest import Tenant
from tests.console.browser import open_page, shot, sign_in
from tests.server.test_missions_formats import SIMPLE_SQUARE_PLAN

pytestmark = pytest.mark.slow  # a browser: not in the fast lane

PORTO = (41.178, -8.598)
FIRST = (47.398742, 8.546594)  # the fixture's first waypoint


async def test_a_far_mission_is_drawn_with_its_base_and_said_to_be_far(
    live_server, api, superuser_email, browser, tmp_path
):
    from playwright.async_api import expect

    tenant = await asyncio.to_thread(Tenant, api, superuser_email, "reach")
    base = await asyncio.to_thread(
        tenant.create_asset,
        "landing_base",
        attributes={"latitude": PORTO[0], "longitude": PORTO[1]},
    )
    await asyncio.to_thread(tenant.create_asset, "uav", base_id=base["id"])
    plan = tmp_path / "simple_square.plan"
    plan.write_text(SIMPLE_SQUARE_PLAN)

    page, traffic = await open_page(browser, live_server.url + "/")
    await sign_in(page, tenant.emails["operator"], Tenant.PASSWORD)
    await page.get_by_role("link", name="Missions").click()
    await page.get_by_label("QGroundControl .plan or waypoint file").set_input_files(str(plan))
    await page.get_by_label("Name (optional)").fill("zurich square")
    await page.get_by_role("button", name="Import").click()

    figure = page.locator("section figure")
    await expect(figure.locator("figcaption")).to_contain_text(f"around base {base['name']}")
    far = haversine_m(*PORTO, *FIRST)
    notice = figure.get_by_role("status")
    await expect(notice).to_contain_text(
        f"the mission's first item is {far / 1000:,.1f} km from base {base['name']}"
    )
    svg = figure.locator("svg.plot")
    await expect(svg.locator("text", has_text="base at the centre")).to_have_count(1)
    # both on the one map: the base's mark and the mission's four waypoints, inside its frame
    marks = [svg.locator("rect.base"), *[svg.locator("circle.wp").nth(k) for k in range(4)]]
    await expect(svg.locator("circle.wp")).to_have_count(4)
    # the frame once it is drawn (read before the waypoints, it was the one being replaced: None)
    box = await svg.bounding_box()
    for mark in marks:
        b = await mark.bounding_box()
        assert b is not None and box is not None
        assert box["x"] <= b["x"] and b["x"] + b["width"] <= box["x"] + box["width"], (b, box)
        assert box["y"] <= b["y"] and b["y"] + b["height"] <= box["y"] + box["height"], (b, box)
    await expect(svg.locator("path.leg")).to_have_count(1)  # the flights there and back
    # the check, from the base with its UAV: out of reach, with the distance and the limit
    checked = page.locator("section table").filter(has_text="out_of_reach")
    await expect(checked).to_contain_text(f"is {far / 1000:,.1f} km from base {base['name']}")
    await expect(checked).to_contain_text("the UAV's reach from it is 2.3 km")
    await shot(page, "mission-far-from-base")
    await page.screenshot(path=str(tmp_path / "far.png"))
    assert traffic.errors == [] and traffic.off_origin(live_server.url) == []
    await page.context.close()
