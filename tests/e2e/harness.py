"""The whole platform in one test process, every boundary real: the simulated world (Modbus TCP,
RTCM3 over TCP, MAVLink over UDP), the server on a socket, both daemons with their server links."""

from __future__ import annotations

import asyncio
import base64
import contextlib
import json
import time
from collections.abc import AsyncIterator, Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import httpx

from aerobase.ports import free_port
from asset_agent.config import AgentConfig
from asset_agent.main import run as run_agent
from asset_agent.main import setup as setup_agent
from assetlink.configfile import decrypt_config
from base_station.main import run as run_base
from base_station.main import setup as setup_base
from base_station.server_link import link_runner, make_link
from sim.assemble import full_world
from sim.plc.model import BaseParams
from sim.vehicle.copter import CopterConfig
from sim.vehicle.habits import Habits
from sim.world import World, WorldConfig
from tests.base_station.bs_helpers import station_config
from tests.conftest import Tenant
from tests.e2e.base_process import BaseDaemon

SPEED = 10.0
FINAL = ("completed", "incomplete", "aborted", "failed")


def mission_items(lat: float, lon: float) -> list[dict[str, Any]]:
    """Take off from the pad, fly a small square at 15 m, return to launch (the base)."""
    square = [(0.0003, 0.0), (0.0003, 0.0004), (0.0, 0.0004)]
    items = [
        {"command": 22, "frame": 3, "params": [0, 0, 0, None], "lat": lat, "lon": lon, "alt": 15}
    ]
    items += [
        {
            "command": 16,
            "frame": 3,
            "params": [0, 0, 0, None],
            "lat": lat + dn,
            "lon": lon + de,
            "alt": 15,
        }
        for dn, de in square
    ]
    items.append({"command": 20, "frame": 3, "params": [0, 0, 0, 0], "lat": 0, "lon": 0, "alt": 0})
    return items


@dataclass
class Platform:
    """A running platform and handles to act on it."""

    world: World
    tenant: Tenant
    api: httpx.AsyncClient
    ids: dict[str, str]
    tasks: dict[str, asyncio.Task[None]]
    stops: dict[str, asyncio.Event]
    agent: Any
    base: Any
    base_daemon: BaseDaemon | None = None  # when the base runs as its own process
    make_agent: Callable[[], Any] | None = None  # a new agent on the same config and state file

    async def restart_agent(self) -> None:
        """Stop the agent daemon and start a new one, as a service manager restarts a crashed
        daemon."""
        await self.stop_agent()
        self.start_agent()

    async def stop_agent(self) -> None:
        """Stop the agent daemon: its run() ends; its outbox stays on disk."""
        self.stops["agent"].set()
        await asyncio.wait_for(self.tasks["agent"], 20)

    def start_agent(self) -> None:
        """A new agent daemon on the same configuration and state file."""
        assert self.make_agent is not None
        self.agent = self.make_agent()
        self.stops["agent"] = asyncio.Event()
        self.tasks["agent"] = asyncio.create_task(run_agent(self.agent, self.stops["agent"]))

    @property
    def copter(self) -> Any:
        """The simulated vehicle's autopilot model (ground truth, fault injection)."""
        return next(part for part in self.world.parts if part.name == "vehicle").server.copter

    async def ready(self, limit_s: float = 30) -> None:
        """Wait until both daemons report live telemetry: the UAV with a 3D fix, the base with its PLC up."""
        deadline = time.monotonic() + limit_s
        while time.monotonic() < deadline:
            uav = await self.api.get(
                f"/api/v1/assets/{self.ids['uav_id']}/telemetry/latest",
                headers=self.tenant.h("viewer"),
            )
            base = await self.api.get(
                f"/api/v1/assets/{self.ids['base_id']}/telemetry/latest",
                headers=self.tenant.h("viewer"),
            )
            if (
                uav.status_code == base.status_code == 200
                and base.json().get("plc_link") == "up"
                and uav.json().get("gnss.fix") in ("3d", "dgps", "rtk_float", "rtk_fixed")
                and base.json().get("uav_present")
            ):
                return
            await asyncio.sleep(0.1)
        raise AssertionError("the daemons did not report ready telemetry")

    async def uav_events(self) -> list[dict[str, Any]]:
        """The UAV's events as the server stores them, oldest first."""
        r = await self.api.get(
            f"/api/v1/assets/{self.ids['uav_id']}/events", headers=self.tenant.h("viewer")
        )
        assert r.status_code == 200, r.text
        return list(r.json())

    async def start_run(self) -> str:
        r = await self.api.post("/api/v1/runs", json=self.ids, headers=self.tenant.h("operator"))
        assert r.status_code == 201, r.text
        return str(r.json()["id"])

    async def run_state(self, run_id: str) -> dict[str, Any]:
        return dict(
            (await self.api.get(f"/api/v1/runs/{run_id}", headers=self.tenant.h("viewer"))).json()
        )

    async def wait_state(
        self, run_id: str, states: tuple[str, ...], limit_s: float = 120
    ) -> dict[str, Any]:
        deadline = time.monotonic() + limit_s
        body: dict[str, Any] = {}
        while time.monotonic() < deadline:
            body = await self.run_state(run_id)
            if body["state"] in states:
                return body
            await asyncio.sleep(0.1)
        raise AssertionError(
            f"run {run_id} did not reach {states}: {body.get('state')} {body.get('timeline')}"
        )


@contextlib.asynccontextmanager
async def platform(
    server_url: str,
    tenant: Tenant,
    tmp: Path,
    *,
    seed: int = 21,
    speed: float = SPEED,
    agent_server_url: str | None = None,
    precland: dict[str, Any] | None = None,
    habits: Habits | None = None,
    pad: tuple[float, float, float] | None = None,
    plan: dict[str, Any] | None = None,
    base_process: bool = False,
    metrics_ports: dict[str, int] | None = None,
    video: dict[str, Any] | None = None,
    local_rtk: bool = False,
) -> AsyncIterator[Platform]:
    """World + daemons connected to the server at `server_url`, assets registered in `tenant`.

    `precland`: the agent's [precland] section (the world's camera and IR ports are filled in);
    None leaves precision landing off (the UAV lands on RTK GNSS alone). `habits`: the simulated
    autopilot's (sim/vehicle/habits.py); `pad`: where the base stands (lat, lon, alt); `plan`: a
    QGroundControl plan imported as the run's mission instead of the pad square. `base_process`:
    the base daemon runs as its own `aerobase base-station` process (`Platform.base_daemon`), to
    be killed. `metrics_ports`: {"base": port, "agent": port} turns on the daemons' own /metrics.
    `video`: the UAV's camera description ({"width", "height", "fps"}); the agent publishes the
    world's downward camera at that size ([video], loopback ICE: the server must allow it too).
    `local_rtk`: the base serves its RTCM3 stream on a local port and the agent reads it there
    (base [rtk] serve_port, agent [rtk] local_source), beside the server's relay."""
    extra = {"base": BaseParams(pad_geodetic=pad)} if pad else {}
    world = full_world(WorldConfig.for_tests(speed=speed, seed=seed, **extra))
    if habits is not None:
        vehicle = next(part for part in world.parts if part.name == "vehicle")
        vehicle.config = CopterConfig(seed=seed, habits=habits)  # type: ignore[attr-defined]
    async with world:
        world.weather.force(wind_mps=2.0, gust_mps=3.0, rain_mm_h=0.0, temperature_c=15.0)
        lat, lon, _ = world.base.pad_geodetic
        base = tenant.create_asset("landing_base", attributes={"latitude": lat, "longitude": lon})
        camera = {"camera": video} if video is not None else {}
        uav = tenant.create_asset("uav", base_id=base["id"], attributes={"mass_g": 1450, **camera})
        async with httpx.AsyncClient(base_url=server_url, timeout=30) as api:
            if plan is not None:
                r = await api.post(
                    "/api/v1/missions/import",
                    headers={**tenant.h("operator"), "content-type": "application/json"},
                    content=json.dumps(plan).encode(),
                )
            else:
                r = await api.post(
                    "/api/v1/missions",
                    headers=tenant.h("operator"),
                    json={"name": "pad square", "items": mission_items(lat, lon)},
                )
            assert r.status_code == 201, r.text
            ids = {"mission_id": r.json()["id"], "uav_id": uav["id"], "base_id": base["id"]}
            bcfg = decrypt_config(base64.b64decode(base["config_file"]), "asset-password-123")
            ucfg = decrypt_config(base64.b64decode(uav["config_file"]), "asset-password-123")
            sconf = station_config(world.ports["plc"], speed, stable_s=1.0)
            sconf = sconf.model_copy(
                update={"rtk": sconf.rtk.model_copy(update={"tcp_port": world.ports["gnss"]})}
            )
            rtk_port = free_port() if local_rtk else 0
            if rtk_port:
                rtk = {"serve_host": "127.0.0.1", "serve_port": rtk_port}
                sconf = sconf.model_copy(update={"rtk": sconf.rtk.model_copy(update=rtk)})
            ports = metrics_ports or {}
            if "base" in ports:
                sconf = sconf.model_copy(
                    update={"metrics": sconf.metrics.model_copy(update={"port": ports["base"]})}
                )
            base_app = setup_base(sconf)
            aconf = AgentConfig.model_validate(
                {
                    "server": {
                        "state_file": str(tmp / "agent.db"),
                        "url": agent_server_url or server_url,
                    },
                    "autopilot": {
                        "url": f"udpout:127.0.0.1:{world.ports['mavlink_udp']}",
                        "link_timeout_s": 2.0,
                    },
                    "telemetry": {"rate_hz": 5},
                    **(
                        {"rtk": {"local_source": f"tcp://127.0.0.1:{rtk_port}"}} if rtk_port else {}
                    ),
                    **({"metrics": {"port": ports["agent"]}} if "agent" in ports else {}),
                    **(
                        {
                            "precland": {
                                "camera_port": world.ports["camera"],
                                "ir_port": world.ports["ir"],
                                **precland,
                            }
                        }
                        if precland is not None
                        else {}
                    ),
                    **(
                        {
                            "video": {
                                "enabled": True,
                                "camera_port": world.ports["camera"],
                                "allow_loopback_ice": True,
                                **video,
                            }
                        }
                        if video is not None
                        else {}
                    ),
                }
            )
            agent = setup_agent(aconf, ucfg)
            stops = {"base": asyncio.Event(), "agent": asyncio.Event()}
            tasks = {"agent": asyncio.create_task(run_agent(agent, stops["agent"]))}
            daemon = None
            if base_process:
                sconf = sconf.model_copy(
                    update={"server": sconf.server.model_copy(update={"url": server_url})}
                )
                daemon = BaseDaemon(
                    sconf,
                    base64.b64decode(base["config_file"]),
                    "asset-password-123",
                    tmp / "base-process",
                )
                daemon.start()
            else:
                link = link_runner(make_link(bcfg, tmp / "base.db", server_url))
                tasks["base"] = asyncio.create_task(run_base(base_app, stops["base"], link=link))
            p = Platform(
                world, tenant, api, ids, tasks, stops, agent, base_app, daemon,
                make_agent=lambda: setup_agent(aconf, ucfg),
            )  # fmt: skip
            try:
                await p.ready()
                yield p
            finally:
                if daemon is not None:
                    await asyncio.to_thread(daemon.stop)
                for name, task in tasks.items():
                    stops[name].set()
                    with contextlib.suppress(Exception):
                        await asyncio.wait_for(task, 20)
