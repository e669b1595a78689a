"""`aerobase demo`: the whole platform on one machine, one real autonomous mission, then keeps serving.

Starts the server (SQLite), the simulated world, a landing-base daemon and a UAV agent as separate
processes; registers an organisation, a user and both assets through the public API (writing their
encrypted configuration files); schedules a survey mission a few seconds ahead and prints the run's
progress live from the operator WebSocket. `--once` exits after the run (0 if it completed);
otherwise it keeps serving, with the URL and credentials printed, until Ctrl-C stops every process.
"""

from __future__ import annotations

import argparse
import asyncio
import base64
import json
import os
import secrets
import shutil
import signal
import socket
import subprocess
import sys
import time
from collections.abc import Sequence
from datetime import UTC, datetime, timedelta
from pathlib import Path
from typing import Any

import httpx
import websockets

PASSWORD_LEN = 18


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _say(message: str) -> None:
    print(f"[demo {datetime.now().strftime('%H:%M:%S')}] {message}", flush=True)


class Processes:
    """The child processes, stopped together (SIGINT, then SIGTERM, then SIGKILL)."""

    def __init__(self, folder: Path) -> None:
        self.folder = folder
        self.children: list[tuple[str, subprocess.Popen[bytes]]] = []

    def start(self, name: str, args: list[str], env: dict[str, str]) -> subprocess.Popen[bytes]:
        log = open(self.folder / f"{name}.log", "wb")
        proc = subprocess.Popen(
            [sys.executable, "-m", "aerobase.cli", *args],
            env={**os.environ, **env},
            stdout=log,
            stderr=subprocess.STDOUT,
            start_new_session=True,
        )
        self.children.append((name, proc))
        return proc

    def check(self) -> None:
        for name, proc in self.children:
            if proc.poll() is not None:
                raise RuntimeError(
                    f"{name} exited with {proc.returncode}; see {self.folder / (name + '.log')}"
                )

    def stop(self) -> None:
        for sig, wait in ((signal.SIGINT, 10), (signal.SIGTERM, 5), (signal.SIGKILL, 5)):
            alive = [(n, p) for n, p in self.children if p.poll() is None]
            for _, p in alive:
                p.send_signal(sig)
            for _, p in alive:
                try:
                    p.wait(wait)
                except subprocess.TimeoutExpired:
                    pass


async def _wait_http(url: str, procs: Processes, limit_s: float = 60) -> None:
    deadline = time.monotonic() + limit_s
    async with httpx.AsyncClient() as c:
        while time.monotonic() < deadline:
            procs.check()
            try:
                if (await c.get(url, timeout=1)).status_code < 500:
                    return
            except httpx.HTTPError:
                pass
            await asyncio.sleep(0.1)
    raise RuntimeError(f"{url} did not answer within {limit_s:.0f} s")


def _write_secret(path: Path, data: bytes | str) -> None:
    path.write_bytes(data if isinstance(data, bytes) else data.encode())
    path.chmod(0o600)


def _survey_polygon(lat: float, lon: float) -> dict[str, Any]:
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


async def _api(
    c: httpx.AsyncClient, method: str, path: str, token: str | None = None, **kw: Any
) -> Any:
    headers = {"Authorization": f"Bearer {token}"} if token else {}
    r = await c.request(method, path, headers=headers, **kw)
    if r.status_code >= 400:
        raise RuntimeError(f"{method} {path} -> {r.status_code}: {r.text}")
    return (
        r.json()
        if r.content and r.headers.get("content-type", "").startswith("application/json")
        else r
    )


ROOT_EMAIL, OPS_EMAIL = "root@demo.aerobase", "ops@demo.aerobase"


def prepare(args: argparse.Namespace) -> tuple[Path, dict[str, str], dict[str, str]]:
    """A fresh folder, the environment of every process, the generated passwords, the superuser."""
    folder = Path(args.dir).resolve()
    shutil.rmtree(folder, ignore_errors=True)
    folder.mkdir(parents=True)
    secrets_ = {name: secrets.token_urlsafe(PASSWORD_LEN) for name in ("root", "ops", "asset")}
    env = {
        "DATABASE_URL": f"sqlite+aiosqlite:///{folder / 'aerobase.db'}",
        "AEROBASE_PUBLIC_URL": f"http://127.0.0.1:{args.port}",
        "AEROBASE_LOG_FORMAT": "json",
    }
    _say(f"files, logs and the database go to {folder}")
    r = subprocess.run(
        [
            sys.executable,
            "-m",
            "aerobase.cli",
            "admin",
            "create-superuser",
            "--email",
            ROOT_EMAIL,
            "--password",
            secrets_["root"],
        ],
        env={**os.environ, **env},
        capture_output=True,
        text=True,
    )
    if r.returncode:
        raise RuntimeError(f"create-superuser failed: {r.stderr.strip()}")
    return folder, env, secrets_


async def demo(
    args: argparse.Namespace, folder: Path, env: dict[str, str], pw: dict[str, str]
) -> int:
    """Run the demo; returns the exit status."""
    procs = Processes(folder)
    server_url = f"http://127.0.0.1:{args.port}"
    ports = {k: _free_port() for k in ("plc", "gnss", "mavlink", "control")}
    root_email, root_pw, ops_email, ops_pw, asset_pw = (
        ROOT_EMAIL,
        pw["root"],
        OPS_EMAIL,
        pw["ops"],
        pw["asset"],
    )
    try:
        _say(f"starting the simulated world at {args.speed:g}x real time (ports {ports})")
        procs.start(
            "world",
            [
                "sim",
                "world",
                "--speed",
                str(args.speed),
                "--seed",
                str(args.seed),
                "--plc-port",
                str(ports["plc"]),
                "--gnss-port",
                str(ports["gnss"]),
                "--mavlink-port",
                str(ports["mavlink"]),
                "--control-port",
                str(ports["control"]),
            ],
            env,
        )
        _say(f"starting the server on {server_url}")
        procs.start("server", ["server", "--port", str(args.port)], env)
        await _wait_http(f"http://127.0.0.1:{ports['control']}/health", procs)
        async with httpx.AsyncClient() as sim:  # the camera and IR sensor pick their own ports
            served = (await sim.get(f"http://127.0.0.1:{ports['control']}/health")).json()["ports"]
        ports.update({k: served[k] for k in ("camera", "ir") if k in served})
        await _wait_http(f"{server_url}/api/health", procs)
        async with httpx.AsyncClient(base_url=server_url, timeout=30) as c:
            token = (
                await _api(
                    c, "POST", "/api/v1/auth/login", json={"email": root_email, "password": root_pw}
                )
            )["access_token"]
            org = await _api(c, "POST", "/api/v1/organizations", token, json={"name": "Demo Fleet"})
            token = (
                await _api(
                    c,
                    "POST",
                    "/api/v1/auth/login",
                    json={
                        "email": root_email,
                        "password": root_pw,
                        "force": True,
                        "organization_id": org["id"],
                    },
                )
            )["access_token"]
            await _api(
                c,
                "POST",
                "/api/v1/users",
                token,
                json={"email": ops_email, "password": ops_pw, "role": "admin"},
            )
            await _api(c, "POST", "/api/v1/auth/logout", token)
            ops = (
                await _api(
                    c, "POST", "/api/v1/auth/login", json={"email": ops_email, "password": ops_pw}
                )
            )["access_token"]
            base = await _api(
                c,
                "POST",
                "/api/v1/assets",
                ops,
                json={"name": "base-porto-1", "kind": "landing_base", "password": asset_pw},
            )
            uav = await _api(
                c,
                "POST",
                "/api/v1/assets",
                ops,
                json={
                    "name": "uav-porto-1",
                    "kind": "uav",
                    "password": asset_pw,
                    "base_id": base["id"],
                    "attributes": {"mass_g": 1450, "endurance_s": 1500, "cruise_speed_mps": 8},
                },
            )
            _say(
                "registered organisation 'Demo Fleet', user ops@demo.aerobase, base-porto-1 and uav-porto-1"
            )
            _write_secret(folder / "asset-password", asset_pw)
            _write_secret(folder / "base.abcf", base64.b64decode(base["config_file"]))
            _write_secret(folder / "uav.abcf", base64.b64decode(uav["config_file"]))
            (folder / "base.toml").write_text(_base_toml(folder, ports, args.speed))
            (folder / "agent.toml").write_text(_agent_toml(folder, ports))
            _say("starting the landing-base daemon and the UAV agent")
            procs.start(
                "base-station", ["base-station", "--config", str(folder / "base.toml")], env
            )
            procs.start("agent", ["agent", "--config", str(folder / "agent.toml")], env)
            lat, lon = await _ready(c, ops, base["id"], uav["id"], procs)
            await _api(
                c,
                "PATCH",
                f"/api/v1/assets/{base['id']}",
                ops,
                json={"attributes": {"latitude": lat, "longitude": lon}},
            )  # surveyed: the UAV sits on it
            mission = await _api(
                c,
                "POST",
                "/api/v1/missions",
                ops,
                json={
                    "name": "north field survey",
                    "kind": "survey",
                    "home": {"lat": lat, "lon": lon},
                    "survey": {
                        "polygon": _survey_polygon(lat, lon),
                        "footprint": {"width_m": 20, "height_m": 15},
                        "side_overlap_pct": 30,
                        "front_overlap_pct": 60,
                        "altitude_m": 25,
                        "speed_mps": 8,
                        "camera_trigger": False,
                    },
                },
            )
            due = datetime.now(UTC) + timedelta(seconds=5)
            await _api(
                c,
                "POST",
                "/api/v1/schedules",
                ops,
                json={
                    "name": "demo survey",
                    "mission_id": mission["id"],
                    "uav_id": uav["id"],
                    "base_id": base["id"],
                    "kind": "once",
                    "at": due.isoformat(),
                },
            )
            _say(
                f"scheduled '{mission['name']}' ({len(mission['items'])} items) for {due:%H:%M:%S} UTC"
            )
            outcome = await _watch(server_url, ops, base["id"], uav["id"], procs)
            runs = await _api(c, "GET", "/api/v1/runs", ops)
            if runs:
                report = await _api(c, "GET", f"/api/v1/runs/{runs[0]['id']}/report", ops)
                ft = report.get("flight_time_s")
                _say(
                    f"run {runs[0]['id']}: {outcome}"
                    + (f"; {ft:.0f} s in the air (wall clock)" if ft else "")
                )
        if args.once:
            return 0 if outcome == "completed" else 1
        print(
            f"""
Aerobase is running on {server_url}  (API docs: {server_url}/api/docs)
  operator login : {ops_email} / {ops_pw}
  superuser      : {root_email} / {root_pw}
  asset password : in {folder / "asset-password"}
  simulator      : control API http://127.0.0.1:{ports["control"]} (faults, weather, ground truth)
Press Ctrl-C to stop everything.""",
            flush=True,
        )
        stop = asyncio.Event()
        loop = asyncio.get_running_loop()
        for sig in (signal.SIGINT, signal.SIGTERM):
            loop.add_signal_handler(sig, stop.set)
        while not stop.is_set():
            procs.check()
            try:
                await asyncio.wait_for(stop.wait(), 1.0)
            except TimeoutError:
                pass
        return 0
    except RuntimeError as err:
        _say(f"failed: {err}")
        return 1
    finally:
        _say("stopping every process")
        procs.stop()


def _base_toml(folder: Path, ports: dict[str, int], speed: float) -> str:
    return f"""# written by aerobase demo
telemetry_hz = 2.0

[plc]
host = "127.0.0.1"
port = {ports["plc"]}
poll_hz = 10.0

[motion]
panels_travel_s = {12.0 / speed:.3f}
lift_travel_s = {8.0 / speed:.3f}

[uav]
min_mass_g = 1200.0
max_mass_g = 1800.0
scale_tare_g = 15.0
stable_s = {max(0.5, 3.0 / speed):.2f}

[server]
config_file = "{folder / "base.abcf"}"
password_file = "{folder / "asset-password"}"
state_file = "{folder / "base-link.db"}"

[rtk]
tcp_host = "127.0.0.1"
tcp_port = {ports["gnss"]}
"""


def _agent_toml(folder: Path, ports: dict[str, int]) -> str:
    return f"""# written by aerobase demo
[server]
config_file = "{folder / "uav.abcf"}"
password_file = "{folder / "asset-password"}"
state_file = "{folder / "agent-link.db"}"

[autopilot]
url = "tcp:127.0.0.1:{ports["mavlink"]}"

[telemetry]
rate_hz = 5
""" + (
        f"""
[precland]
camera_port = {ports["camera"]}
ir_port = {ports["ir"]}
"""
        if "camera" in ports and "ir" in ports
        else ""
    )


async def _ready(
    c: httpx.AsyncClient, token: str, base_id: str, uav_id: str, procs: Processes
) -> tuple[float, float]:
    """Wait until both daemons report: the base's PLC up with the UAV on its scale, the UAV with a fix.

    Returns the UAV's position: it stands on the pad."""
    deadline = time.monotonic() + 90
    while time.monotonic() < deadline:
        procs.check()
        h = {"Authorization": f"Bearer {token}"}
        b = await c.get(f"/api/v1/assets/{base_id}/telemetry/latest", headers=h)
        u = await c.get(f"/api/v1/assets/{uav_id}/telemetry/latest", headers=h)
        if (
            b.status_code == u.status_code == 200
            and b.json().get("plc_link") == "up"
            and b.json().get("uav_present")
            and u.json().get("gnss.fix") in ("3d", "dgps", "rtk_float", "rtk_fixed")
        ):
            _say(
                f"both daemons are reporting: base PLC up, UAV on the scale, UAV GNSS {u.json()['gnss.fix']}"
            )
            return float(u.json()["position.lat"]), float(u.json()["position.lon"])
        await asyncio.sleep(0.2)
    raise RuntimeError(
        "the daemons did not report within 90 s (see base-station.log and agent.log)"
    )


async def _watch(server_url: str, token: str, base_id: str, uav_id: str, procs: Processes) -> str:
    """Print run progress from the operator WebSocket until the run ends; returns its outcome."""
    url = server_url.replace("http", "ws", 1) + f"/ws/operator?token={token}"
    async with websockets.connect(url) as ws:
        await ws.send(
            json.dumps(
                {
                    "v": 1,
                    "type": "subscribe",
                    "id": "00000000-0000-4000-8000-000000000001",
                    "seq": 0,
                    "ts": 0,
                    "payload": {"asset_ids": [base_id, uav_id]},
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
                _say(f"{'!!' if p.get('alert') else '=='} {p['label']}: {p['reason']}")
                return str(p["state"])
            _say(
                f"{'!!' if p.get('alert') else '->'} [{p['step']}/{p['total_steps']}] {p['label']}: {p['reason']}"
            )
    raise RuntimeError("the run did not end within 10 minutes")


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of `aerobase demo`."""
    parser = argparse.ArgumentParser(prog="aerobase demo", description=__doc__.splitlines()[0])
    parser.add_argument("--once", action="store_true", help="exit after the run: 0 if it completed")
    parser.add_argument("--port", type=int, default=8000)
    parser.add_argument(
        "--speed", type=float, default=5.0, help="simulated seconds per wall second"
    )
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--dir", default="var/demo", help="where files, logs and the database go")
    args = parser.parse_args(argv)
    try:
        folder, env, passwords = prepare(args)
    except (OSError, RuntimeError) as err:
        _say(f"failed: {err}")
        return 1
    return asyncio.run(demo(args, folder, env, passwords))
