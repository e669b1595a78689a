"""The demo's walk through the public API: an organisation, its users and assets, a scheduled
survey, and the run's progress from the operator WebSocket."""

from __future__ import annotations

import asyncio
import json
import time
from dataclasses import dataclass
from datetime import UTC, datetime, timedelta
from typing import Any

import httpx
import websockets

from aerobase.demo.daemons import DEMO_CAMERA
from aerobase.demo.processes import Processes, say

ROOT_EMAIL, OPS_EMAIL = "root@demo.aerobase", "ops@demo.aerobase"
# the demo's own account: it holds a session for the whole demo (its watch, the video link it
# prints), so the operator login it prints signs in on first use without taking anything over
DEMO_EMAIL = "demo@demo.aerobase"


@dataclass(frozen=True)
class Fleet:
    """What registration made: the demo's own token and the two assets as the API returned them."""

    token: str
    base: dict[str, Any]
    uav: dict[str, Any]


async def api(
    c: httpx.AsyncClient, method: str, path: str, token: str | None = None, **kw: Any
) -> Any:
    """One API call: its JSON body (or the response when there is none); RuntimeError on >= 400."""
    headers = {"Authorization": f"Bearer {token}"} if token else {}
    r = await c.request(method, path, headers=headers, **kw)
    if r.status_code >= 400:
        raise RuntimeError(f"{method} {path} -> {r.status_code}: {r.text}")
    return (
        r.json()
        if r.content and r.headers.get("content-type", "").startswith("application/json")
        else r
    )


async def _login(c: httpx.AsyncClient, email: str, password: str, **extra: Any) -> str:
    body = {"email": email, "password": password, **extra}
    return str((await api(c, "POST", "/api/v1/auth/login", json=body))["access_token"])


async def register(c: httpx.AsyncClient, passwords: dict[str, str]) -> Fleet:
    """As the superuser: the organisation, its operator (for the one watching) and the demo's own
    user; as the demo's user: the base and the UAV."""
    token = await _login(c, ROOT_EMAIL, passwords["root"])
    org = await api(c, "POST", "/api/v1/organizations", token, json={"name": "Demo Fleet"})
    token = await _login(c, ROOT_EMAIL, passwords["root"], force=True, organization_id=org["id"])
    for email, password in ((OPS_EMAIL, passwords["ops"]), (DEMO_EMAIL, passwords["demo"])):
        await api(
            c,
            "POST",
            "/api/v1/users",
            token,
            json={"email": email, "password": password, "role": "admin"},
        )
    await api(c, "POST", "/api/v1/auth/logout", token)
    own = await _login(c, DEMO_EMAIL, passwords["demo"])
    base = await api(
        c,
        "POST",
        "/api/v1/assets",
        own,
        json={"name": "base-porto-1", "kind": "landing_base", "password": passwords["asset"]},
    )
    uav = await api(
        c,
        "POST",
        "/api/v1/assets",
        own,
        json={
            "name": "uav-porto-1",
            "kind": "uav",
            "password": passwords["asset"],
            "base_id": base["id"],
            "attributes": {
                "mass_g": 1450,
                "endurance_s": 1500,
                "cruise_speed_mps": 8,
                "camera": DEMO_CAMERA,
            },
        },
    )
    say(
        f"registered organisation 'Demo Fleet', users {OPS_EMAIL} and {DEMO_EMAIL} (the demo's "
        "own), base-porto-1 and uav-porto-1"
    )
    return Fleet(own, base, uav)


async def announce_video(c: httpx.AsyncClient, fleet: Fleet, server_url: str) -> bool:
    """Wait (up to 30 s) for the UAV's camera to be live and say where to watch it."""
    path = f"/api/v1/assets/{fleet.uav['id']}/video"
    deadline = time.monotonic() + 30
    while time.monotonic() < deadline:
        video = await api(c, "GET", path, fleet.token)
        if video["state"] == "live":
            say(
                f"live video of uav-porto-1 ({video['width']}x{video['height']} VP8, "
                f"{video['measured_fps'] or video['fps']} fps): {server_url}/video/viewer"
                f"#asset={fleet.uav['id']}&token={fleet.token}"
            )
            return True
        await asyncio.sleep(0.5)
    say("the UAV's video is not live after 30 s (see agent.log); the mission goes on")
    return False


async def wait_ready(c: httpx.AsyncClient, fleet: Fleet, procs: Processes) -> tuple[float, float]:
    """Wait until both daemons report: the base's PLC up with the UAV on its scale, the UAV with a fix.

    Returns the UAV's position: it stands on the pad."""
    deadline = time.monotonic() + 90
    h = {"Authorization": f"Bearer {fleet.token}"}
    while time.monotonic() < deadline:
        procs.check()
        b = await c.get(f"/api/v1/assets/{fleet.base['id']}/telemetry/latest", headers=h)
        u = await c.get(f"/api/v1/assets/{fleet.uav['id']}/telemetry/latest", headers=h)
        if (
            b.status_code == u.status_code == 200
            and b.json().get("plc_link") == "up"
            and b.json().get("uav_present")
            and u.json().get("gnss.fix") in ("3d", "dgps", "rtk_float", "rtk_fixed")
            # the fix (GPS_RAW_INT) can be reported a sample before the position
            # (GLOBAL_POSITION_INT): a loaded run once read the one without the other
            and u.json().get("position.lat") is not None
            and u.json().get("position.lon") is not None
        ):
            say(
                f"both daemons are reporting: base PLC up, UAV on the scale, UAV GNSS {u.json()['gnss.fix']}"
            )
            return float(u.json()["position.lat"]), float(u.json()["position.lon"])
        await asyncio.sleep(0.2)
    raise RuntimeError(
        "the daemons did not report within 90 s (see base-station.log and agent.log)"
    )


async def wait_uav_available(c: httpx.AsyncClient, fleet: Fleet, procs: Processes) -> None:
    """Ask the UAV `check_availability` (as an operator's console does) until it answers available.

    An external autopilot that has just booted fails its pre-arm checks for 30-45 s (ArduPilot:
    EKF, GPS, home); a survey scheduled before it is armable would abort at step 1."""
    deadline = time.monotonic() + 180
    h = {"Authorization": f"Bearer {fleet.token}"}
    told = ""
    while time.monotonic() < deadline:
        procs.check()
        sent = await c.post(
            f"/api/v1/assets/{fleet.uav['id']}/commands",
            json={"name": "check_availability", "params": {}, "timeout_s": 10},
            headers=h,
        )
        sent.raise_for_status()
        status, reason = "queued", ""
        while status in ("queued", "sent", "in_progress") and time.monotonic() < deadline:
            await asyncio.sleep(0.3)
            got = (await c.get(f"/api/v1/commands/{sent.json()['id']}", headers=h)).json()
            status, reason = got["status"], got.get("reason") or ""
        if status == "succeeded":
            say("the UAV is available (its autopilot passes its pre-arm checks)")
            return
        if reason != told:
            say(f"waiting for the UAV to be available: {reason or status}")
            told = reason
        await asyncio.sleep(2.0)
    raise RuntimeError(f"the UAV was not available within 180 s: {told} (see agent.log)")


def survey_polygon(lat: float, lon: float) -> dict[str, Any]:
    """A 60 m x 40 m field starting 20 m north of the base."""
    dlat, dlon = 1 / 111_320, 1 / (111_320 * 0.7527)  # metres to degrees near 41° N
    n0, n1, e0, e1 = 20 * dlat, 80 * dlat, -20 * dlon, 20 * dlon
    ring = [
        [lon + e0, lat + n0],
        [lon + e1, lat + n0],
        [lon + e1, lat + n1],
        [lon + e0, lat + n1],
        [lon + e0, lat + n0],
    ]
    return {"type": "Polygon", "coordinates": [ring]}


async def schedule_survey(c: httpx.AsyncClient, fleet: Fleet, lat: float, lon: float) -> None:
    """Survey the base where the UAV stands, plan the north field and schedule it 5 s ahead."""
    ops, base_id = fleet.token, fleet.base["id"]
    await api(
        c,
        "PATCH",
        f"/api/v1/assets/{base_id}",
        ops,
        json={"attributes": {"latitude": lat, "longitude": lon}},
    )  # surveyed: the UAV sits on it
    survey = {
        "polygon": survey_polygon(lat, lon),
        "footprint": {"width_m": 20, "height_m": 15},
        "side_overlap_pct": 30,
        "front_overlap_pct": 60,
        "altitude_m": 25,
        "speed_mps": 8,
        "camera_trigger": False,
    }
    mission = await api(
        c,
        "POST",
        "/api/v1/missions",
        ops,
        json={
            "name": "north field survey",
            "kind": "survey",
            "home": {"lat": lat, "lon": lon},
            "survey": survey,
        },
    )
    due = datetime.now(UTC) + timedelta(seconds=5)
    schedule = {
        "name": "demo survey",
        "mission_id": mission["id"],
        "uav_id": fleet.uav["id"],
        "base_id": base_id,
        "kind": "once",
        "at": due.isoformat(),
    }
    await api(c, "POST", "/api/v1/schedules", ops, json=schedule)
    say(f"scheduled '{mission['name']}' ({len(mission['items'])} items) for {due:%H:%M:%S} UTC")


async def watch(server_url: str, fleet: Fleet, procs: Processes) -> str:
    """Print run progress from the operator WebSocket until the run ends; returns its outcome."""
    url = server_url.replace("http", "ws", 1) + f"/ws/operator?token={fleet.token}"
    async with websockets.connect(url) as ws:
        await ws.send(
            json.dumps(
                {
                    "v": 1,
                    "type": "subscribe",
                    "id": "00000000-0000-4000-8000-000000000001",
                    "seq": 0,
                    "ts": 0,
                    "payload": {"asset_ids": [fleet.base["id"], fleet.uav["id"]]},
                }
            )
        )
        deadline = time.monotonic() + 600
        while time.monotonic() < deadline:
            procs.check()
            try:
                msg = json.loads(await asyncio.wait_for(ws.recv(), 1.0))
            except TimeoutError:
                continue
            if msg.get("type") != "run_progress":
                continue
            p = msg["payload"]
            if p.get("final"):
                say(f"{'!!' if p.get('alert') else '=='} {p['label']}: {p['reason']}")
                return str(p.get("outcome") or p["state"])  # whether the job was done
            say(
                f"{'!!' if p.get('alert') else '->'} [{p['step']}/{p['total_steps']}] {p['label']}: {p['reason']}"
            )
    raise RuntimeError("the run did not end within 10 minutes")


async def report_run(c: httpx.AsyncClient, fleet: Fleet, outcome: str) -> None:
    """Print the outcome of the latest run with its flight time, its timeline and what the UAV
    reported meanwhile (armed, took_off, mission_finished, landed, ...)."""
    runs = await api(c, "GET", "/api/v1/runs", fleet.token)
    if not runs:
        return
    report = await api(c, "GET", f"/api/v1/runs/{runs[0]['id']}/report", fleet.token)
    ft = report.get("flight_time_s")
    say(f"run {runs[0]['id']}: {outcome}" + (f"; {ft:.0f} s in the air (wall clock)" if ft else ""))
    landing = report.get("landing") or {}
    if landing.get("agent_offset_m") is not None:
        fix = landing.get("agent_fix_height_m")
        seen = f", the agent's last fix {fix:.2f} m above the pad" if fix is not None else ""
        weighed = "weighed" if landing.get("base_confirmed") else "did not weigh"
        say(
            f"landed {100 * landing['agent_offset_m']:.1f} cm from the pad's centre "
            f"({landing.get('agent_landing_path')}{seen}, {landing.get('agent_fix_sources')}); "
            f"the base {weighed} it"
        )
    timeline = report["run"]["timeline"]
    say("timeline: " + " -> ".join(f"{t['to_state']} ({t['reason']})" for t in timeline))
    if timeline:
        events = await api(
            c,
            "GET",
            f"/api/v1/assets/{fleet.uav['id']}/events",
            fleet.token,
            params={"start": timeline[0]["at"]},
        )
        say("UAV events: " + ", ".join(e["name"] for e in events))
