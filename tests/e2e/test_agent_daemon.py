"""The companion-computer daemon end to end: simulated autopilot over MAVLink UDP, real server."""

from __future__ import annotations

import asyncio
import base64
import contextlib
import time
from collections.abc import AsyncIterator
from pathlib import Path

import httpx
import pytest

from asset_agent.config import AgentConfig
from asset_agent.main import Agent, run, setup
from assetlink.configfile import AssetConfig, decrypt_config
from sim.vehicle.server import VehicleServer, run_vehicle
from sim.vehicle.standalone import OpenPad
from tests.conftest import Tenant
from tests.polling import eventually

pytestmark = pytest.mark.slow  # whole processes end to end: not in the fast lane


async def _command(
    c: httpx.AsyncClient,
    tenant: Tenant,
    asset_id: str,
    name: str,
    params: dict | None = None,
    limit_s: float = 30.0,
) -> dict:
    r = await c.post(
        f"/api/v1/assets/{asset_id}/commands",
        json={"name": name, "params": params or {}, "timeout_s": limit_s},
        headers=tenant.h("operator"),
    )
    assert r.status_code == 202, r.text
    cid = r.json()["id"]
    deadline = time.monotonic() + limit_s + 5
    while time.monotonic() < deadline:
        body = (await c.get(f"/api/v1/commands/{cid}", headers=tenant.h("viewer"))).json()
        if body["status"] in ("succeeded", "rejected", "failed", "timed_out", "canceled"):
            return dict(body)
        await asyncio.sleep(0.05)
    raise AssertionError(f"command {name} did not finish")


@contextlib.asynccontextmanager
async def _agent(
    vehicle: VehicleServer, cfg: AssetConfig, tmp_path: Path, rate_hz: float
) -> AsyncIterator[Agent]:
    """The agent daemon's run() between `vehicle` (MAVLink over UDP) and the live server,
    reporting telemetry at `rate_hz`; stopped on exit."""
    config = AgentConfig.model_validate(
        {
            "server": {"state_file": str(tmp_path / "agent.db")},
            "autopilot": {"url": f"udpout:127.0.0.1:{vehicle.udp_port}", "link_timeout_s": 2.0},
            "telemetry": {"rate_hz": rate_hz},
        }
    )
    agent = setup(config, cfg)
    stop = asyncio.Event()
    task = asyncio.create_task(run(agent, stop))
    try:
        yield agent
    finally:
        stop.set()
        await asyncio.wait_for(task, 20)


def _mission(lat: float, lon: float) -> list[dict]:
    items = [
        {
            "command": 22,
            "frame": 3,
            "params": [0, 0, 0, None],
            "lat": lat,
            "lon": lon,
            "alt": 10,
            "autocontinue": True,
        }
    ]
    for i in range(4):
        items.append(
            {
                "command": 16,
                "frame": 3,
                "params": [0, 0, 0, None],
                "lat": lat + 0.0001 * (i + 1),
                "lon": lon,
                "alt": 10,
                "autocontinue": True,
            }
        )
    items.append(
        {
            "command": 20,
            "frame": 3,
            "params": [0, 0, 0, 0],
            "lat": 0,
            "lon": 0,
            "alt": 0,
            "autocontinue": True,
        }
    )
    return items


async def test_agent_reports_telemetry_and_answers_commands(live_server, tenant: Tenant, tmp_path):
    asset = tenant.create_asset("uav")
    cfg = decrypt_config(base64.b64decode(asset["config_file"]), "asset-password-123")
    pad = OpenPad()
    async with (
        run_vehicle(speed=10.0, seed=3, base=pad) as vehicle,
        _agent(vehicle, cfg, tmp_path, 5),
    ):
        async with httpx.AsyncClient(base_url=live_server.url) as c:

            async def latest() -> dict | None:
                r = await c.get(
                    f"/api/v1/assets/{asset['id']}/telemetry/latest", headers=tenant.h("viewer")
                )
                return r.json() if r.status_code == 200 else None

            deadline = time.monotonic() + 30
            row = None
            while time.monotonic() < deadline and not (row and "position.lat" in row):
                row = await latest()
                await asyncio.sleep(0.1)
            assert row and abs(row["position.lat"] - pad.pad_geodetic[0]) < 0.001
            assert row["landed_state"] == "on_ground" and row["armed"] is False

            check = await _command(c, tenant, asset["id"], "check_availability")
            assert check["status"] in ("succeeded", "failed"), check
            assert isinstance(check["result"]["failed"], list)
            assert {c["name"] for c in check["result"]["conditions"]} >= {"battery", "gnss_fix"}
            if check["status"] == "failed":
                assert check["reason"] and all("message" in f for f in check["result"]["failed"])

            lat, lon, _ = pad.pad_geodetic
            up = await _command(
                c, tenant, asset["id"], "upload_mission", {"items": _mission(lat, lon)}
            )
            assert up["status"] == "succeeded", up
            assert up["result"]["count"] == 6
            steps = [
                h["status"]
                for h in (
                    await c.get(f"/api/v1/commands/{up['id']}", headers=tenant.h("viewer"))
                ).json()["history"]
            ]
            assert (
                steps[:2] == ["queued", "sent"]
                and "in_progress" in steps
                and steps[-1] == "succeeded"
            )

            # an item out of range or an unknown command never reaches the agent: the
            # server checks both against protocol.vocabulary (the agent's own refusal of
            # them is in tests/protocol/test_assetlink_dispatch.py)
            item = {"command": 16, "frame": 3, "params": [0, 0, 0, 0], "lat": 123.0, "alt": 10}
            bad = await c.post(
                f"/api/v1/assets/{asset['id']}/commands",
                headers=tenant.h("operator"),
                json={"name": "upload_mission", "params": {"items": [item]}},
            )
            assert bad.status_code == 422 and "items.0.lat" in bad.text
            unknown = await c.post(
                f"/api/v1/assets/{asset['id']}/commands",
                headers=tenant.h("operator"),
                json={"name": "teleport"},
            )
            assert unknown.status_code == 422 and "unknown command" in unknown.text


async def test_the_availability_check_reads_the_autopilots_precision_landing_switches(
    live_server, tenant: Tenant, tmp_path
):
    """In mode landing_target the autopilot's own precision landing must take our
    LANDING_TARGETs: ArduPilot does only with PLND_ENABLED = 1 and PLND_TYPE = 1 (both default to
    0, and then it drops them and lands on GNSS). The agent's availability check reads both and
    says what to set; an autopilot without them (no ArduPilot PLND) is not held back."""
    asset = tenant.create_asset("uav")
    cfg = decrypt_config(base64.b64decode(asset["config_file"]), "asset-password-123")
    async with run_vehicle(speed=10.0, seed=3, base=OpenPad()) as vehicle:
        config = AgentConfig.model_validate(
            {
                "server": {"state_file": str(tmp_path / "agent.db")},
                "autopilot": {
                    "url": f"udpout:127.0.0.1:{vehicle.udp_port}",
                    "link_timeout_s": 2.0,
                    "command_timeout_s": 0.3,
                },
                "precland": {"enabled": True},  # mode landing_target, the default
            }
        )
        agent = setup(config, cfg)
        stop = asyncio.Event()
        task = asyncio.create_task(run(agent, stop))
        copter = vehicle.copter

        async def plnd_condition(c: httpx.AsyncClient) -> tuple[dict, dict]:
            check = await _command(c, tenant, asset["id"], "check_availability")
            assert check["status"] in ("succeeded", "failed"), check
            (cond,) = [x for x in check["result"]["conditions"] if x["name"] == "precision_landing"]
            return check, cond

        try:
            async with httpx.AsyncClient(base_url=live_server.url) as c:
                await eventually(lambda: agent.link.connected, 30, "the agent connected")
                await eventually(lambda: agent.autopilot.link_up, 30, "the autopilot's HEARTBEAT")
                check, cond = await plnd_condition(c)
                assert cond["ok"] and "PLND_TYPE = 1" in cond["message"], cond["message"]
                assert cond not in check["result"]["failed"]

                assert copter.set_param("PLND_ENABLED", 0)  # ArduPilot's default
                check, cond = await plnd_condition(c)
                assert not cond["ok"] and check["status"] == "failed", check
                assert cond in check["result"]["failed"]
                assert "PLND_ENABLED = 0" in cond["message"] in check["reason"]
                assert 'mode = "companion"' in cond["message"]

                assert copter.set_param("PLND_ENABLED", 1) and copter.set_param("PLND_TYPE", 2)
                check, cond = await plnd_condition(c)
                assert not cond["ok"] and "PLND_TYPE = 2" in cond["message"], cond

                for name in ("PLND_ENABLED", "PLND_TYPE"):  # an autopilot without ArduPilot PLND
                    del copter.fence.params[name]
                check, cond = await plnd_condition(c)
                assert cond["ok"] and "has no PLND_ENABLED" in cond["message"], cond
        finally:
            stop.set()
            await task


async def test_the_last_waypoint_reached_is_reported_before_the_mission_end_it_makes(
    live_server, tenant: Tenant, tmp_path
):
    """A mission ending at a plain waypoint: the autopilot's MISSION_ITEM_REACHED of it is what
    ends the mission, so both reach the agent in one telemetry tick; its events say them in that
    order (derived from the latest state alone, the end came first)."""
    asset = tenant.create_asset("uav")
    cfg = decrypt_config(base64.b64decode(asset["config_file"]), "asset-password-123")
    pad = OpenPad()
    async with (
        run_vehicle(speed=10.0, seed=5, base=pad) as vehicle,
        _agent(vehicle, cfg, tmp_path, 1) as agent,
    ):
        lat, lon, _ = pad.pad_geodetic
        takeoff, *rest = _mission(lat, lon)
        mission = [takeoff, rest[0]]  # take off, one waypoint: the last item
        async with httpx.AsyncClient(base_url=live_server.url) as c:
            await eventually(lambda: agent.autopilot.link_up, 30, "the autopilot's HEARTBEAT")
            up = await _command(c, tenant, asset["id"], "upload_mission", {"items": mission})
            assert up["status"] == "succeeded", up
            go = await _command(c, tenant, asset["id"], "start_mission")
            assert go["status"] == "succeeded", go

            async def names() -> list[tuple[str, object]]:
                r = await c.get(f"/api/v1/assets/{asset['id']}/events", headers=tenant.h("viewer"))
                return [(e["name"], e["data"].get("index")) for e in r.json()]

            async def finished() -> bool:
                return ("mission_finished", None) in await names()

            await eventually(finished, 60, "the mission finished")
            told = [e for e in await names() if e[0] in ("waypoint_reached", "mission_finished")]
            assert told == [
                ("waypoint_reached", 0), ("waypoint_reached", 1), ("mission_finished", None),
            ]  # fmt: skip
