"""The operator console in a real browser (Debian's Chromium) against the whole platform: the
simulated world, both daemons and the server, every boundary real."""

from __future__ import annotations

import asyncio
import json
import math
import re
from datetime import UTC, datetime, timedelta
from pathlib import Path

import pytest

from tests.conftest import Tenant
from tests.console.browser import open_page, shot, sign_in
from tests.e2e.harness import platform
from tests.polling import eventually

pytestmark = pytest.mark.slow  # a browser and the whole platform: not in the fast lane

PAGE_WEIGHT_LIMIT = 300_000  # bytes transferred, compressed, for the first load (issue 18)
CAMERA = {"width": 320, "height": 240, "fps": 15}  # the UAV's camera: the world's render, scaled


def _bad_plan(lat: float, lon: float) -> bytes:
    """A QGroundControl plan with one good item and one the platform refuses (a VTOL take-off)."""
    item = {
        "type": "SimpleItem", "autoContinue": True, "frame": 3, "AltitudeMode": 1, "Altitude": 20,
        "AMSLAltAboveTerrain": None,
    }  # fmt: skip
    items = [
        {**item, "command": 22, "doJumpId": 1, "params": [0, 0, 0, None, lat, lon, 20]},
        {**item, "command": 84, "doJumpId": 2, "params": [0, 0, 0, None, lat, lon, 20]},
    ]
    plan = {
        "fileType": "Plan", "version": 1, "groundStation": "QGroundControl",
        "mission": {"version": 2, "firmwareType": 3, "vehicleType": 2, "cruiseSpeed": 15,
                    "hoverSpeed": 5, "items": items, "plannedHomePosition": [lat, lon, 100]},
        "geoFence": {"circles": [], "polygons": [], "version": 2},
        "rallyPoints": {"points": [], "version": 2},
    }  # fmt: skip
    return json.dumps(plan).encode()


async def _frames_over(video, n: int) -> bool:  # type: ignore[no-untyped-def]
    return int(await video.get_attribute("data-frames") or 0) > n


def _ms(iso: str) -> int:
    """Unix milliseconds of an ISO time, truncated as the browser's Date.parse does."""
    at = datetime.fromisoformat(iso.replace("Z", "+00:00"))
    return (at - datetime(1970, 1, 1, tzinfo=UTC)) // timedelta(milliseconds=1)


class _RecordedFrames:
    """The recorded frame the replay shows at a moment: the last segment begun by 0.5 s after
    it, and in it the last frame received by then (or its first), as (segment, seconds)."""

    def __init__(self, api, headers: dict[str, str], uav_id: str) -> None:  # type: ignore[no-untyped-def]
        self.api, self.headers, self.uav_id = api, headers, uav_id
        self.times: dict[str, list[dict[str, int]]] = {}

    async def __call__(self, moment: float) -> tuple[str, float]:
        rows = (
            await self.api.get(
                f"/api/v1/assets/{self.uav_id}/video/recordings?limit=1000", headers=self.headers
            )
        ).json()
        segment = max(
            (r for r in rows if _ms(r["started_at"]) <= moment + 500),
            key=lambda r: _ms(r["started_at"]),
        )
        if segment["name"] not in self.times:
            text = (await self.api.get(segment["times_url"], headers=self.headers)).text
            lines = text.split("\n")  # a segment being written may end in a half-written line
            self.times[segment["name"]] = [json.loads(x) for x in lines[:-1]]
        times = self.times[segment["name"]]
        frame = ([x for x in times if x["t"] <= moment] or times[:1])[-1]
        return segment["name"], frame["pts"] / 90000


async def _numbers(locator) -> float | None:  # type: ignore[no-untyped-def]
    text = await locator.inner_text()
    m = re.search(r"-?\d+(?:\.\d+)?", text)
    return float(m.group()) if m else None


async def test_an_operator_watches_the_fleet_schedules_a_run_to_completion_and_reads_its_report(
    database_url, superuser_email, tmp_path, browser
):
    import httpx

    from tests.conftest import LiveServer, test_settings

    # a server whose video relay offers loopback candidates, as the agent's [video] does here, and
    # records what it relays (the replay plays it back)
    settings = test_settings(
        database_url,
        video_ice_loopback=True,
        video_record_dir=tmp_path / "recordings",
        video_record_segment_s=10.0,  # the run spans several segments, most of them closed
    )
    server = LiveServer(settings).start()
    try:
        with httpx.Client(base_url=server.url) as sync_api:
            tenant = await asyncio.to_thread(Tenant, sync_api, superuser_email, "console")
            await _operator_story(server, tenant, tmp_path, browser)
    finally:
        await asyncio.to_thread(server.stop)


async def _operator_story(live_server, tenant: Tenant, tmp_path, browser) -> None:  # type: ignore[no-untyped-def]
    from playwright.async_api import expect

    # at 3x the square flies ~15 s wall: a page on a busy machine (its three requests queued
    # behind the server's video relay) still shows the flight, and the fleet page its altitudes
    # (at 10x the flight lasted 4.4 s and the page drew it only from the closing on)
    async with platform(live_server.url, tenant, tmp_path, video=CAMERA, speed=3.0) as p:
        uav = (await p.api.get(f"/api/v1/assets/{p.ids['uav_id']}", headers=tenant.h())).json()
        base = (await p.api.get(f"/api/v1/assets/{p.ids['base_id']}", headers=tenant.h())).json()
        page, traffic = await open_page(browser, live_server.url + "/")
        await shot(page, "sign-in")
        # the harness holds a live session for the operator: the page explains the one-session rule
        await sign_in(page, tenant.emails["operator"], Tenant.PASSWORD)

        # the fleet: both assets with live state
        uav_card = page.get_by_role("region", name=f"UAV {uav['name']}")
        base_card = page.get_by_role("region", name=f"Landing base {base['name']}")
        await expect(uav_card).to_contain_text("connected")
        await expect(uav_card).to_contain_text(
            re.compile(r"GNSS fix\s*(3d|dgps|rtk_float|rtk_fixed)")
        )
        await expect(uav_card).to_contain_text(re.compile(r"Battery\s*\d+ %"))
        await expect(base_card).to_contain_text(re.compile(r"PLC link\s*up"))
        await expect(base_card).to_contain_text(re.compile(r"Panels\s*closed"))
        await expect(base_card).to_contain_text(re.compile(r"Weather\s*wind \d"))
        # a go/no-go needs a check: the operator asks for one, confirms, and sees the outcome
        await base_card.get_by_role("button", name=f"Check availability: {base['name']}").click()
        dialog = page.get_by_role("dialog", name="Check availability")
        await dialog.get_by_role("button", name="Check availability").click()
        await expect(base_card.get_by_role("status")).to_contain_text("succeeded", timeout=30_000)
        await expect(base_card).to_contain_text(re.compile(r"Go / no-go\s*GO all conditions met"))
        # the UAV's live camera: WHEP through the shared client, decoded frames counted by the page
        video_state = uav_card.get_by_role("status", name=f"Video state of {uav['name']}")
        await expect(video_state).to_have_text("live", timeout=60_000)
        video = uav_card.get_by_label(f"Live video of {uav['name']}")
        await eventually(lambda: _frames_over(video, 30), 60, "30 decoded video frames")
        size = await video.evaluate("v => [v.videoWidth, v.videoHeight]")
        assert size == [CAMERA["width"], CAMERA["height"]], size
        weight = traffic.total()
        # one sign-in renders the fleet once: each asset's latest sample asked for once
        latest = [u for u in traffic.urls if u.endswith("/telemetry/latest")]
        assert sorted(latest) == sorted(set(latest)) and len(latest) <= 2, latest
        await shot(page, "fleet")

        # a mission file with a refused item: every problem is named by item
        await page.get_by_role("link", name="Missions").click()
        await page.get_by_label("QGroundControl .plan or waypoint file").set_input_files(
            {"name": "vtol.plan", "mimeType": "application/json", "buffer": _bad_plan(41.0, -8.0)}
        )
        await page.get_by_role("button", name="Import").click()
        problems = page.get_by_role("table", name=re.compile("problem"))
        await expect(problems).to_contain_text("84 NAV_VTOL_TAKEOFF")
        await expect(problems).to_contain_text("unsupported command")
        await page.get_by_role("link", name="Open mission pad square").click()
        await expect(page.get_by_role("img", name=re.compile("Mission pad square"))).to_be_visible()
        await shot(page, "missions")
        async with page.expect_download() as download:
            await page.get_by_role(
                "button", name="Export pad square as a QGroundControl plan"
            ).click()
        saved = await (await download.value).path()
        exported = json.loads(await asyncio.to_thread(Path(saved).read_text))
        assert exported["fileType"] == "Plan" and len(exported["mission"]["items"]) == 5

        # schedule a one-shot run a few seconds ahead, from the mission
        await page.get_by_role("link", name="Runs").click()
        await expect(page.get_by_role("heading", name="Runs", exact=True)).to_be_visible()
        await page.get_by_label("Mission", exact=True).select_option(label="pad square")
        await page.get_by_label("UAV", exact=True).select_option(label=uav["name"])
        await page.get_by_label("When", exact=True).select_option("once")
        at = datetime.now(UTC) + timedelta(seconds=6)
        await page.get_by_label("At (your local time)").fill(at.strftime("%Y-%m-%dT%H:%M:%S"))
        await page.get_by_role("button", name="Start or schedule").click()
        await expect(page.get_by_role("table", name="Schedules")).to_contain_text("once at")
        # the scheduler starts it; the page shows it without a reload
        open_run = page.get_by_role("link", name=re.compile("^Open run of"))
        await expect(open_run.first).to_be_visible(timeout=60_000)
        await open_run.first.click()
        steps = page.get_by_role("list", name="Steps of the run")
        try:
            await expect(steps.locator('[aria-current="step"]')).to_contain_text(
                "Flying the mission", timeout=90_000
            )
        except AssertionError as err:  # what the run did meanwhile, with the server's times
            run = await p.run_state(page.url.rsplit("/", 1)[-1])
            times = [(t["at"], t["from_state"], t["to_state"]) for t in run.get("timeline", [])]
            raise AssertionError(f"run {run.get('state')}: {times}") from err
        await shot(page, "run-live")
        run_url = page.url

        # the fleet page follows the flight: the altitude changes without a reload
        await page.get_by_role("link", name="Fleet").click()
        altitude = uav_card.get_by_role("definition").nth(6)
        seen = set()

        async def climbing() -> bool:
            value = await _numbers(altitude)
            if value is not None and value > 1:
                seen.add(value)
            return len(seen) >= 3

        await eventually(climbing, 60, "three different altitudes on the fleet page")
        # the UAV's events arrive on the same page as they happen
        events = page.get_by_role("table", name="Recent events (newest first)")
        await expect(events).to_contain_text(uav["name"])
        item = uav_card.get_by_role("definition").nth(7)
        await expect(item).to_have_text(re.compile("^[345] of 5"), timeout=30_000)
        await shot(page, "fleet-flying")

        # back to the run: its timeline reaches completed
        await page.goto(run_url)
        run_title = page.get_by_role("heading", name=re.compile("^Run of"))
        await expect(run_title).to_be_visible()
        detail = page.get_by_role("region", name=re.compile("^Run of"))
        await expect(detail.get_by_text("completed", exact=True)).to_be_visible(timeout=150_000)
        await expect(detail.get_by_role("table", name="Timeline")).to_contain_text(
            "charging → completed"
        )
        assert await steps.locator('[aria-current="step"]').count() == 0

        # schedules: a cron in a time zone; one that never fires is refused with the server's reason
        await page.get_by_label("When", exact=True).select_option("cron")
        await page.get_by_label("Schedule name").fill("dawn patrol")
        await page.get_by_label("Cron (minute hour day month weekday)").fill("0 0 31 2 *")
        await page.get_by_label("Time zone (IANA)").fill("Europe/Lisbon")
        await page.get_by_role("button", name="Start or schedule").click()
        form = page.get_by_role("form", name="Start or schedule a run")
        await expect(form.get_by_role("alert")).to_contain_text("never fires")
        await page.get_by_label("Cron (minute hour day month weekday)").fill("0 6 * * *")
        await page.get_by_role("button", name="Start or schedule").click()
        schedules = page.get_by_role("table", name="Schedules")
        await expect(schedules).to_contain_text("cron 0 6 * * * (Europe/Lisbon)")
        await schedules.get_by_role("button", name="Delete schedule dawn patrol").click()
        await (
            page.get_by_role("dialog", name="Delete the schedule")
            .get_by_role("button", name="Delete")
            .click()
        )
        await expect(schedules).not_to_contain_text("dawn patrol")

        # its report: figures and the five plots, drawn from the stored telemetry
        await detail.get_by_role("link", name="Open the run report").click()
        await expect(page.get_by_role("heading", name="Run report")).to_be_visible()
        for name in ("Altitude", "Battery", "Ground speed", "Landing error", "Flight track"):
            plot = page.get_by_role("img", name=re.compile(f"^{name}: "))
            await expect(plot).to_have_attribute(
                "aria-label", re.compile(r"\d+ (samples|track points)")
            )
            assert "no samples" not in (await plot.get_attribute("aria-label")), name
        await shot(page, "report")
        await page.get_by_role("link", name="Replay this run").click()
        slider = page.get_by_label("Time in the run")
        await slider.focus()
        for _ in range(40):
            await slider.press("ArrowRight")
        await expect(page.get_by_role("definition").first).not_to_have_text("pending")
        # back to a moment in flight (0.5 s a key): its recorded video, a segment fetched
        # with the token and played from a blob: URL at that moment's frame
        # (the first moment the run's step is `flying`: where it falls in the run depends on how
        # fast this machine flew the 3x square, so the slider walks there rather than guessing)
        # Where the page must put the video is read from the server's recording (the segment and
        # its frame-times file); a moment on a segment's first frame is at 0 s, so the walk goes on
        # through `flying` to a frame inside a segment, one that shows the page positioned it.
        steps = 2 * int(float(await slider.get_attribute("max") or 0)) + 1
        await slider.press("Home")
        step = page.get_by_role("definition").first
        frame_at = _RecordedFrames(p.api, tenant.h(), uav["id"])
        created = _ms((await p.run_state(run_url.rsplit("/", 1)[-1]))["created_at"])
        segment, at_s = "", 0.0
        for _ in range(steps):
            if "flying" in (await step.text_content() or ""):
                moment = created + float(await slider.input_value()) * 1000
                segment, at_s = await frame_at(moment)
                if at_s >= 0.5:
                    break
            await slider.press("ArrowRight")
        await expect(step).to_contain_text("flying")
        assert at_s >= 0.5, (segment, at_s)
        recorded = page.get_by_role("status", name="Recorded video state")
        await expect(recorded).to_have_text(f"recorded · {segment}", timeout=30_000)
        playback = page.get_by_label("Recorded video of the run")
        media = "v => [v.readyState, v.seeking, v.currentTime, v.duration, v.error && v.error.code]"

        async def playable() -> bool:
            ready, seeking, at, _, _ = await playback.evaluate(media)
            return ready >= 2 and not seeking and abs(at - at_s) < 0.02

        try:
            await eventually(playable, 30, "the recorded frame of that moment")
        except AssertionError as err:
            raise AssertionError(f"{err}: {await playback.evaluate(media)}") from None
        shown = await playback.evaluate("v => [v.videoWidth, v.videoHeight, v.currentTime]")
        assert shown[:2] == [CAMERA["width"], CAMERA["height"]] and shown[2] > 0, shown
        await playback.evaluate("v => v.closest('figure').scrollIntoView({block: 'end'})")
        await shot(page, "replay")
        await page.get_by_role("link", name="History").click()
        await expect(page.get_by_role("table", name=re.compile("Past runs"))).to_contain_text(
            "completed"
        )
        await shot(page, "history")
        # a tablet held upright: one column, nothing wider than the screen
        for name in ("Fleet", "Runs", "History"):
            await page.set_viewport_size({"width": 768, "height": 1024})
            await page.get_by_role("link", name=name, exact=True).click()
            await expect(page.get_by_role("heading", name=name, exact=True)).to_be_visible()
            wide = await page.evaluate("document.documentElement.scrollWidth - innerWidth")
            assert wide <= 0, (name, wide)
        await shot(page, "history-tablet")

        assert traffic.errors == []
        assert traffic.off_origin(live_server.url) == [], traffic.off_origin(live_server.url)
        print(f"first load to a live fleet: {weight} bytes transferred")
        assert weight < PAGE_WEIGHT_LIMIT, weight
        body = await p.run_state(
            (await p.api.get("/api/v1/runs", headers=tenant.h())).json()[0]["id"]
        )
        assert body["state"] == "completed" and body["schedule_id"], body["state"]
        await page.context.close()


async def test_abort_in_flight_from_the_page_while_a_viewer_sees_no_controls_and_another_organisation_sees_nothing(
    live_server, api, superuser_email, tenant: Tenant, tmp_path, browser
):
    from playwright.async_api import expect

    # at 2x the square lasts ~10 s wall: time for a browser (and a person) to abort it in the air
    async with platform(live_server.url, tenant, tmp_path, speed=2.0) as p:
        uav = (await p.api.get(f"/api/v1/assets/{p.ids['uav_id']}", headers=tenant.h())).json()
        r = await p.api.post("/api/v1/runs", json=p.ids, headers=tenant.h("admin"))
        assert r.status_code == 201, r.text
        run_id = r.json()["id"]
        run_url = f"{live_server.url}/#/runs/{run_id}"

        viewer, viewer_traffic = await open_page(browser, live_server.url + "/")
        await sign_in(viewer, tenant.emails["viewer"], Tenant.PASSWORD)
        operator, operator_traffic = await open_page(browser, live_server.url + "/")
        await sign_in(operator, tenant.emails["operator"], Tenant.PASSWORD)
        for page in (viewer, operator):
            await page.goto(run_url)
            steps = page.get_by_role("list", name="Steps of the run")
            await expect(steps.locator('[aria-current="step"]')).to_contain_text(
                "Flying the mission", timeout=90_000
            )
        # the viewer: the same run, live, without a control
        await expect(viewer.get_by_role("heading", name=re.compile("^Run of"))).to_be_visible()
        assert await viewer.locator("main").get_by_role("button").count() == 0
        await shot(viewer, "run-viewer")
        await eventually(
            lambda: (p.agent.autopilot.state.alt_rel or 0) > 10, 60, "the UAV to climb out"
        )
        # the operator aborts in flight, with a confirmation and a reason
        await operator.get_by_role("button", name="Abort run").click()
        dialog = operator.get_by_role("dialog", name="Abort the run")
        await dialog.get_by_label("Reason (written in the timeline)").fill("airspace closed")
        await dialog.get_by_role("button", name="Abort the run").click()
        detail = operator.get_by_role("region", name=re.compile("^Run of"))
        await expect(detail.get_by_role("button", name="Abort requested")).to_be_disabled()
        # meanwhile the viewer finds no control on any page
        for link in ("Fleet", "Missions", "History"):
            await viewer.get_by_role("link", name=link, exact=True).click()
            await expect(viewer.get_by_role("heading", name=link, exact=True)).to_be_visible()
            if link == "Fleet":
                uav_card = viewer.get_by_role("region", name=f"UAV {uav['name']}")
                await expect(uav_card).to_contain_text("connected")
            assert await viewer.locator("main").get_by_role("button").count() == 0, link
        assert await viewer.get_by_label("QGroundControl .plan or waypoint file").count() == 0
        await expect(detail.get_by_text("aborted", exact=True)).to_be_visible(timeout=150_000)
        timeline = detail.get_by_role("table", name="Timeline")
        await expect(timeline).to_contain_text("flying → landing")
        await expect(timeline).to_contain_text("airspace closed")
        await expect(timeline).to_contain_text("→ aborted")
        await shot(operator, "run-aborted")
        # (the console took the viewer's session over: read as the admin)
        body = (await p.api.get(f"/api/v1/runs/{run_id}", headers=tenant.h("admin"))).json()
        assert body["state"] == "aborted" and body["cause"] == "operator_abort", body["timeline"]

        # a user of another organisation: none of this organisation's assets, runs or missions
        other = await asyncio.to_thread(Tenant, api, superuser_email, "other")
        stranger, stranger_traffic = await open_page(browser, live_server.url + "/")
        await sign_in(stranger, other.emails["operator"], Tenant.PASSWORD)
        await expect(stranger.locator("main")).to_contain_text(
            "This organisation has no assets yet."
        )
        await stranger.goto(run_url)
        await expect(stranger.get_by_role("heading", name="Runs", exact=True)).to_be_visible()
        await expect(stranger.locator("main")).to_contain_text("No runs yet.")
        await stranger.goto(f"{live_server.url}/#/report/{run_id}")
        await expect(stranger.get_by_role("heading", name="Run report")).to_be_visible()
        refused = stranger.get_by_role("alert").filter(has_text="could not be loaded")
        await expect(refused).to_contain_text("not found")
        await stranger.get_by_role("link", name="Missions").click()
        await expect(stranger.locator("main")).to_contain_text("No missions yet.")
        text = await stranger.locator("body").inner_text()
        assert uav["name"] not in text and "pad square" not in text
        for traffic in (viewer_traffic, operator_traffic, stranger_traffic):
            assert traffic.off_origin(live_server.url) == [], traffic.urls
            assert traffic.errors == []
        for page in (viewer, operator, stranger):
            await page.context.close()


async def test_the_console_reconnects_by_itself_after_a_server_restart_and_marks_stale_data(
    database_url, superuser_email, tmp_path, browser
):
    import httpx
    from playwright.async_api import expect

    from tests.conftest import LiveServer, test_settings

    server = LiveServer(test_settings(database_url)).start()
    restarted = None
    try:
        with httpx.Client(base_url=server.url) as sync_api:
            tenant = await asyncio.to_thread(Tenant, sync_api, superuser_email, "restart")
            async with platform(server.url, tenant, tmp_path) as p:
                uav = (
                    await p.api.get(f"/api/v1/assets/{p.ids['uav_id']}", headers=tenant.h())
                ).json()
                page, _ = await open_page(browser, server.url + "/")
                await sign_in(page, tenant.emails["operator"], Tenant.PASSWORD)
                link = page.get_by_role("status").filter(has_text=re.compile("Live|Connect"))
                card = page.get_by_role("region", name=f"UAV {uav['name']}")
                await expect(page.locator("#link")).to_have_text("Live")
                await expect(card).to_contain_text("connected")
                await asyncio.to_thread(server.stop)
                await expect(page.locator("#link")).to_contain_text("reconnecting", timeout=20_000)
                await expect(card).to_contain_text("stale: last data")
                await shot(page, "fleet-reconnecting")
                restarted = await asyncio.to_thread(server.restarted)
                await expect(page.locator("#link")).to_have_text("Live", timeout=30_000)
                await expect(card).to_contain_text("connected", timeout=30_000)
                assert await link.count() == 1
                # the video panel came back by itself too: the UAV sends no video in this world
                video = card.get_by_role("status", name=f"Video state of {uav['name']}")
                await expect(video).to_have_text(re.compile("^no signal"), timeout=30_000)
                # on the restarted server, commands still go out and come back with their outcome
                base = page.get_by_role("region", name=re.compile("^Landing base "))
                for command, panels in (
                    ("Open base", "open · 100 %"),
                    ("Close base", "closed · 0 %"),
                ):
                    await base.get_by_role("button", name=re.compile(f"^{command}: ")).click()
                    await (
                        page.get_by_role("dialog", name=command)
                        .get_by_role("button", name=command)
                        .click()
                    )
                    outcome = base.get_by_role("status")
                    await expect(outcome).to_contain_text(f"{command}: succeeded", timeout=60_000)
                    await expect(base).to_contain_text(f"Panels{panels}")
                assert p.world.base.contacts_seated  # closed over the UAV, which never moved
                await page.context.close()
    finally:
        await asyncio.to_thread((restarted or server).stop)


async def test_a_member_of_two_organisations_chooses_one_and_is_told_when_another_login_ends_the_session(
    live_server, api, superuser_email, database_url, browser
):
    from playwright.async_api import expect

    from server.kit.principal import Role
    from tests.conftest import login
    from tests.server.test_login_hardening import _join

    a = await asyncio.to_thread(Tenant, api, superuser_email, "first")
    b = await asyncio.to_thread(Tenant, api, superuser_email, "second")
    email = a.emails["operator"]
    await _join(database_url, email, b.id, Role.viewer)
    page, traffic = await open_page(browser, live_server.url + "/")
    await page.get_by_label("E-mail").fill(email)
    await page.get_by_label("Password").fill(Tenant.PASSWORD)
    await page.get_by_role("button", name="Sign in").click()
    await page.get_by_role("button", name="Sign in and end the other session").click()
    await page.get_by_label("Organisation").select_option(label=f"{b.name} (viewer)")
    await page.get_by_role("button", name="Continue").click()
    await expect(page.get_by_role("heading", name="Fleet", exact=True)).to_be_visible()
    await expect(page.get_by_role("banner")).to_contain_text(f"{b.name} · viewer")
    await expect(page.locator("#link")).to_have_text("Live")
    # another login takes the session over: the console says so, at once, without a click
    await asyncio.to_thread(login, api, email, Tenant.PASSWORD, force=True)
    ended = page.get_by_role("alert").filter(
        has_text="Your session ended: another login took this session over."
    )
    await expect(ended).to_be_visible(timeout=10_000)
    await expect(page.get_by_role("heading", name="Sign in to Aerobase")).to_be_visible()
    await shot(page, "session-taken-over")
    assert traffic.errors == [] and traffic.off_origin(live_server.url) == []
    await page.context.close()


async def test_an_open_console_renews_its_session_before_it_expires(
    database_url, superuser_email, browser
):
    import time

    import httpx
    from playwright.async_api import expect

    from tests.conftest import LiveServer, test_settings

    server = LiveServer(test_settings(database_url, session_ttl_s=60)).start()
    try:
        with httpx.Client(base_url=server.url) as sync_api:
            tenant = await asyncio.to_thread(Tenant, sync_api, superuser_email, "renew")
            tenant.create_asset("landing_base")
        page, traffic = await open_page(browser, server.url + "/")
        await sign_in(page, tenant.emails["operator"], Tenant.PASSWORD)
        signed_in = time.monotonic()

        first = await _stored_session(page)
        await eventually(
            lambda: _renewed(page, first), 60, "the console to renew its token before expiry"
        )
        # past the first token's 60 s lifetime the console still works, its socket live again
        await eventually(lambda: time.monotonic() - signed_in > 62, 70, "the first expiry")
        await page.get_by_role("link", name="Runs").click()
        await expect(page.get_by_role("heading", name="Runs", exact=True)).to_be_visible()
        await expect(page.get_by_role("heading", name="Sign in to Aerobase")).to_have_count(0)
        await expect(page.locator("#link")).to_have_text("Live")
        assert traffic.errors == []
        await page.context.close()
    finally:
        await asyncio.to_thread(server.stop)


async def _stored_session(page) -> str:  # type: ignore[no-untyped-def]
    return str(await page.evaluate("sessionStorage.getItem('aerobase.session')"))


async def _renewed(page, first: str) -> bool:  # type: ignore[no-untyped-def]
    return await _stored_session(page) not in (first, "None")


async def test_the_map_draws_the_sites_tiles_when_a_tile_server_is_set(
    database_url, superuser_email, browser
):
    import threading
    from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer

    import httpx
    from playwright.async_api import expect

    from tests.conftest import LiveServer, test_settings

    asked: list[str] = []

    class Tiles(BaseHTTPRequestHandler):
        def do_GET(self) -> None:
            asked.append(self.path)
            body = b'<svg xmlns="http://www.w3.org/2000/svg" width="256" height="256"/>'
            self.send_response(200)
            self.send_header("Content-Type", "image/svg+xml")
            self.send_header("Content-Length", str(len(body)))
            self.end_headers()
            self.wfile.write(body)

        def log_message(self, *args: object) -> None:
            pass

    tile_server = ThreadingHTTPServer(("127.0.0.1", 0), Tiles)
    threading.Thread(target=tile_server.serve_forever, daemon=True).start()
    template = f"http://127.0.0.1:{tile_server.server_port}/{{z}}/{{x}}/{{y}}.svg"
    server = LiveServer(test_settings(database_url, map_tile_url=template)).start()
    try:
        with httpx.Client(base_url=server.url) as sync_api:
            tenant = await asyncio.to_thread(Tenant, sync_api, superuser_email, "tiles")
            site = {"latitude": 41.178, "longitude": -8.598}
            base = tenant.create_asset("landing_base", attributes=site)
            uav = tenant.create_asset("uav", base_id=base["id"])
        page, traffic = await open_page(browser, server.url + "/")
        await sign_in(page, tenant.emails["operator"], Tenant.PASSWORD)
        live_map = page.get_by_role("img", name=re.compile(f"^Live track of {uav['name']}"))
        await expect(live_map).to_be_visible()
        assert await live_map.locator("image").count() >= 1
        await eventually(lambda: asked, 10, "the page to ask the tile server for tiles")
        z = int(asked[0].strip("/").split("/")[0])
        assert 15 <= z <= 19, asked  # a site-sized map: a few hundred metres across
        # among the tiles: the one holding the base (web mercator of 41.178 N, 8.598 W)
        n, lat = 2**z, math.radians(41.178)
        x = int((-8.598 + 180) / 360 * n)
        y = int((1 - math.log(math.tan(lat) + 1 / math.cos(lat)) / math.pi) / 2 * n)
        # tiles load one by one: wait for the base's own (the first ones asked may be its
        # neighbours; a snapshot right after the first request missed it once in a full run)
        await eventually(lambda: f"/{z}/{x}/{y}.svg" in asked, 10, f"the base's tile in {asked}")
        assert traffic.errors == []
        await page.context.close()
    finally:
        await asyncio.to_thread(server.stop)
        tile_server.shutdown()


def _plan_through(lat: float, lon: float, north_m: float) -> bytes:
    """A .plan from the base straight north for `north_m` and back, with its own fence circle
    (inclusion, 300 m) and one rally point 50 m east of the base."""
    north = north_m / 111_195.0
    east_50 = 50 / (111_195.0 * math.cos(math.radians(lat)))
    item = {
        "type": "SimpleItem", "autoContinue": True, "frame": 3, "AltitudeMode": 1, "Altitude": 30,
        "AMSLAltAboveTerrain": None,
    }  # fmt: skip
    items = [
        {**item, "command": 22, "doJumpId": 1, "params": [0, 0, 0, None, lat, lon, 30]},
        {**item, "command": 16, "doJumpId": 2, "params": [0, 0, 0, None, lat + north, lon, 30]},
        {**item, "command": 20, "doJumpId": 3, "params": [0, 0, 0, 0, 0, 0, 0]},
    ]
    plan = {
        "fileType": "Plan", "version": 1, "groundStation": "QGroundControl",
        "mission": {"version": 2, "firmwareType": 3, "vehicleType": 2, "cruiseSpeed": 15,
                    "hoverSpeed": 5, "items": items, "plannedHomePosition": [lat, lon, 100]},
        "geoFence": {"circles": [{"circle": {"center": [lat, lon], "radius": 300}, "inclusion": True,
                                  "version": 1}], "polygons": [], "version": 2},
        "rallyPoints": {"points": [[lat, lon + east_50, 20]], "version": 2},
    }  # fmt: skip
    return json.dumps(plan).encode()


async def test_the_maps_draw_the_zones_and_the_plans_fence_and_the_mission_page_names_the_breach(
    live_server, api, tenant: Tenant, browser
):
    from playwright.async_api import expect

    lat, lon = 41.178, -8.598
    base = tenant.create_asset("landing_base", attributes={"latitude": lat, "longitude": lon})
    uav = tenant.create_asset("uav", base_id=base["id"])
    d_lat, d_lon = 1 / 111_195.0, 1 / (111_195.0 * math.cos(math.radians(lat)))

    def square(n0: float, n1: float, e0: float, e1: float) -> dict[str, object]:
        ring = [
            [lon + e * d_lon, lat + n * d_lat] for n, e in ((n0, e0), (n0, e1), (n1, e1), (n1, e0))
        ]
        return {"type": "Polygon", "coordinates": [[*ring, ring[0]]]}

    past = {"start": "2020-01-01T00:00:00Z", "end": "2020-01-02T00:00:00Z"}
    zones = [
        {"name": "school", "kind": "exclusion", "geometry": square(80, 140, -40, 40), "ceiling_m": 60},
        {"name": "fair", "kind": "exclusion", "geometry": square(-120, -60, 60, 140), "windows": [past]},
        {"name": "operating area", "kind": "inclusion", "base_id": base["id"],
         "geometry": {"type": "Point", "coordinates": [lon, lat]}, "radius_m": 250},
    ]  # fmt: skip
    for z in zones:
        r = api.post("/api/v1/airspace/zones", json=z, headers=tenant.h("operator"))
        assert r.status_code == 201, r.text
    r = api.post(
        "/api/v1/missions/import?name=north%20leg",
        content=_plan_through(lat, lon, 200),
        headers={**tenant.h("operator"), "Content-Type": "application/json"},
    )
    assert r.status_code == 201, r.text
    mission = r.json()

    page, traffic = await open_page(browser, live_server.url + "/")
    await sign_in(page, tenant.emails["operator"], Tenant.PASSWORD)
    # the fleet map: every zone that applies to the base, found by the map's accessible name
    live_map = page.get_by_role("img", name=re.compile(f"^Live track of {uav['name']}"))
    await expect(live_map).to_have_accessible_name(re.compile("exclusion zone 'school'"))
    name = await live_map.get_attribute("aria-label")
    assert "exclusion zone 'school', from the ground to ceiling 60 m" in name, name
    assert "exclusion zone 'fair' (inactive now)" in name, name
    assert "inclusion zone 'operating area', from the ground to ceiling 120 m" in name, name
    # drawn: the school hatched, the fair dimmed, the operating area outlined
    assert await live_map.locator("path.zone.exclusion:not(.inactive)").count() == 1
    assert await live_map.locator("path.zone.exclusion.inactive").count() == 1
    assert await live_map.locator("circle.zone.inclusion").count() == 1
    await expect(live_map.locator(".legend")).to_contain_text("exclusion zone (keep out)")
    weight = traffic.total()
    # scrolled by the page itself: live samples redraw the map, and Playwright's own scrolling
    # waits for a stable element that a redraw may detach meanwhile
    await live_map.evaluate("m => m.scrollIntoView({block: 'center'})")
    await shot(page, "fleet-airspace")

    # the mission: its own fence and rally point on its map, and the breach the server names
    await page.goto(f"{live_server.url}/#/missions/{mission['id']}")
    mission_map = page.get_by_role("img", name=re.compile("^Mission north leg"))
    await expect(mission_map).to_have_accessible_name(
        re.compile("plan fence circle 0 \\(inclusion\\)")
    )
    await expect(mission_map).to_have_accessible_name(re.compile("exclusion zone 'school'"))
    await expect(mission_map).to_have_accessible_name(re.compile("1 rally point"))
    problems = page.get_by_role("table", name=re.compile(f"Not valid from {base['name']}"))
    # out and back: both legs cross the school, each named with its segment
    out_leg = problems.get_by_role("row").filter(has_text="items[0] → items[1]")
    await expect(out_leg).to_contain_text("airspace")
    await expect(out_leg).to_contain_text("exclusion zone 'school'")
    await expect(out_leg).to_contain_text(re.compile(r"\b(59\.\d|60\.\d) m"))  # 60 m deep
    back_leg = problems.get_by_role("row").filter(has_text="items[1] → home")
    await expect(back_leg).to_contain_text("school")
    await shot(page, "missions-airspace")
    assert traffic.errors == [], traffic.errors
    assert traffic.off_origin(live_server.url) == [], traffic.off_origin(live_server.url)
    assert weight < PAGE_WEIGHT_LIMIT, weight
    await page.context.close()
