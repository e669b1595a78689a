"""The landing-base daemon end to end: simulated PLC over Modbus TCP and GNSS receiver, real server.

Operators open and close the base through the REST API; the base's telemetry, events and RTK
corrections reach the server; a command replayed after a daemon restart starts no motion.
"""

from __future__ import annotations

import asyncio
import base64
import time

import httpx
import pytest

from assetlink.configfile import decrypt_config
from base_station.main import run, setup
from base_station.server_link import link_runner, make_link
from sim.gnss.part import GnssPart
from sim.world import World, WorldConfig
from tests.base_station.bs_helpers import station_config
from tests.conftest import Tenant
from tests.e2e.test_agent_daemon import _command

pytestmark = pytest.mark.slow  # whole processes end to end: not in the fast lane

SPEED = 10.0


async def test_base_opens_and_closes_on_operator_commands(live_server, tenant: Tenant, tmp_path):
    asset = tenant.create_asset("landing_base")
    cfg = decrypt_config(base64.b64decode(asset["config_file"]), "asset-password-123")
    world = World(WorldConfig.for_tests(speed=SPEED, seed=5))
    world.add_part(GnssPart())
    async with world:
        world.weather.force(wind_mps=2.0, gust_mps=3.0, rain_mm_h=0.0, temperature_c=15.0)
        config = station_config(world.ports["plc"]).model_copy(
            update={
                "rtk": station_config(0).rtk.model_copy(update={"tcp_port": world.ports["gnss"]})
            }
        )
        app = setup(config)
        stop = asyncio.Event()
        link = make_link(cfg, tmp_path / "base-link.db", live_server.url)
        task = asyncio.create_task(run(app, stop, link=link_runner(link)))
        try:
            async with httpx.AsyncClient(base_url=live_server.url) as c:
                opened = await _command(c, tenant, asset["id"], "open", limit_s=30)
                assert opened["status"] == "succeeded", opened
                assert world.base.can_vehicle_leave()
                history = (
                    await c.get(f"/api/v1/commands/{opened['id']}", headers=tenant.h("viewer"))
                ).json()
                progress = [h for h in history["history"] if h["status"] == "in_progress"]
                assert len(progress) >= 2  # panels, then lift

                refused = await _command(c, tenant, asset["id"], "close_panels")
                assert refused["status"] == "rejected" and "lift" in refused["reason"]

                closed = await _command(c, tenant, asset["id"], "close", limit_s=30)
                assert closed["status"] == "succeeded", closed
                assert not world.base.can_vehicle_leave()

                deadline = time.monotonic() + 20
                row = None
                while time.monotonic() < deadline:
                    r = await c.get(
                        f"/api/v1/assets/{asset['id']}/telemetry/latest", headers=tenant.h("viewer")
                    )
                    row = r.json() if r.status_code == 200 else None
                    if (
                        row
                        and row.get("panels.state") == "closed"
                        and row.get("rtk.frames_total", 0) > 0
                    ):
                        break
                    await asyncio.sleep(0.1)
                assert row and row["plc_link"] == "up" and row["panels.state"] == "closed"
                assert row["rtk.frames_total"] > 0 and row["weather.wind_m_s"] >= 0
                events = (
                    await c.get(f"/api/v1/assets/{asset['id']}/events", headers=tenant.h("viewer"))
                ).json()
                assert any(e["name"] == "refusal" and "lift" in e["message"] for e in events)
        finally:
            stop.set()
            await asyncio.wait_for(task, 20)
        # a restart of the daemon (same link state: same session, same command ledger) starts no motion
        before = len(world.base.command_log)
        app2 = setup(config)
        stop2 = asyncio.Event()
        link2 = make_link(cfg, tmp_path / "base-link.db", live_server.url)
        task2 = asyncio.create_task(run(app2, stop2, link=link_runner(link2)))
        try:
            async with httpx.AsyncClient(base_url=live_server.url) as c:
                # a barrier: once a fresh command has been answered, the reconnect and any replay are done
                check = await _command(c, tenant, asset["id"], "check_availability")
                assert check["status"] in ("succeeded", "failed", "rejected"), check
            assert link2.connected
            assert [c.coil for c in world.base.command_log[before:]] == []
        finally:
            stop2.set()
            await asyncio.wait_for(task2, 20)
