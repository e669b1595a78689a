"""`aerobase demo`: the whole platform on one machine, one real autonomous mission, then keeps serving.

Starts the server (SQLite), the simulated world, a landing-base daemon and a UAV agent as separate
processes; registers an organisation, a user and both assets through the public API (writing their
encrypted configuration files); schedules a survey mission a few seconds ahead and prints the run's
progress live from the operator WebSocket. `--once` exits after the run (0 if it completed);
otherwise it keeps serving, with the URL and credentials printed, until Ctrl-C stops every process.

`--autopilot URL --autopilot-watch URL2` flies an external autopilot (ArduPilot SITL, our own
`aerobase sim autopilot`, or a real vehicle's companion link) instead of the simulated one: the
agent flies it on URL and the world follows it read-only on URL2 (`aerobase sim world --follow`),
building the base at its home and rendering the camera, the IR beacon and the scale's load from the
pose it reports. `--speed` must then be the autopilot's own speed-up (1 for real time).
"""

from __future__ import annotations

import argparse
import asyncio
import os
import secrets
import shutil
import subprocess
import sys
from collections.abc import Sequence
from pathlib import Path

import httpx

from aerobase.demo.daemons import write_daemon_files
from aerobase.demo.fleet import (
    OPS_EMAIL,
    ROOT_EMAIL,
    announce_video,
    register,
    report_run,
    schedule_survey,
    wait_ready,
    wait_uav_available,
    watch,
)
from aerobase.demo.processes import Processes, say, serve_until_stopped, wait_http
from aerobase.ports import free_port, port_free
from sim.mavlink_link import BadUrl, parse_url

PASSWORD_LEN = 18
NTRIP_PORT = 2101  # NTRIP casters' own port


def prepare(args: argparse.Namespace) -> tuple[Path, dict[str, str], dict[str, str]]:
    """A fresh folder, the environment of every process, the generated passwords, the superuser."""
    folder = Path(args.dir).resolve()
    shutil.rmtree(folder, ignore_errors=True)
    folder.mkdir(parents=True)
    secrets_ = {
        name: secrets.token_urlsafe(PASSWORD_LEN) for name in ("root", "ops", "demo", "asset")
    }
    env = {
        "DATABASE_URL": f"sqlite+aiosqlite:///{folder / 'aerobase.db'}",
        "AEROBASE_PUBLIC_URL": f"http://127.0.0.1:{args.port}",
        "AEROBASE_LOG_FORMAT": "json",
        # everything runs on this machine: WebRTC peers may use loopback (server/video)
        "AEROBASE_VIDEO_ICE_LOOPBACK": "true",
        # the NTRIP caster for version 1 clients (str2str): 2101 as casters use, if it is free
        "AEROBASE_NTRIP_PORT": str(NTRIP_PORT if port_free(NTRIP_PORT) else free_port()),
    }
    say(f"files, logs and the database go to {folder}")
    create_superuser(ROOT_EMAIL, secrets_["root"], env)
    return folder, env, secrets_


def create_superuser(email: str, password: str, env: dict[str, str]) -> None:
    """`aerobase admin create-superuser` with the password in its environment: off the process
    list, and never read as an option (a generated one may begin with "-")."""
    r = subprocess.run(
        [sys.executable, "-m", "aerobase.cli", "admin", "create-superuser", "--email", email],
        env={**os.environ, **env, "AEROBASE_PASSWORD": password},
        stdin=subprocess.DEVNULL,
        capture_output=True,
        text=True,
    )
    if r.returncode:
        raise RuntimeError(f"create-superuser failed: {r.stderr.strip()}")


async def start_world_and_server(
    args: argparse.Namespace, procs: Processes, env: dict[str, str], server_url: str
) -> dict[str, int]:
    """Start the simulated world and the server; returns the world's ports once both answer."""
    ports = {k: free_port() for k in ("plc", "gnss", "mavlink", "control")}
    world = ["sim", "world", "--speed", str(args.speed), "--seed", str(args.seed)]
    for name in ("plc", "gnss", "mavlink", "control"):
        world += [f"--{name}-port", str(ports[name])]
    limit_s = 60.0
    if args.autopilot:
        world += ["--follow", args.autopilot_watch, "--follow-timeout", str(args.follow_timeout)]
        limit_s += args.follow_timeout
        say(
            f"starting the simulated world at {args.speed:g}x real time around the autopilot "
            f"at {args.autopilot}, followed through {args.autopilot_watch} (ports {ports})"
        )
    else:
        say(f"starting the simulated world at {args.speed:g}x real time (ports {ports})")
    procs.start("world", world, env)
    say(f"starting the server on {server_url}")
    await start_server(args, procs, env, server_url)
    await wait_http(f"http://127.0.0.1:{ports['control']}/health", procs, limit_s)
    async with httpx.AsyncClient() as sim:  # the camera and IR sensor pick their own ports
        served = (await sim.get(f"http://127.0.0.1:{ports['control']}/health")).json()["ports"]
    ports.update({k: served[k] for k in ("camera", "ir") if k in served})
    return ports


async def start_server(
    args: argparse.Namespace, procs: Processes, env: dict[str, str], server_url: str
) -> None:
    """Start the server and wait until it answers. 2101 was free when `prepare` looked, but
    another demo starting beside this one (or any caster) may bind it first: the server then
    exits at start-up, and starts once more with its caster on a free port."""
    for retried in (False, True):
        procs.start("server", ["server", "--port", str(args.port)], env)
        try:
            await wait_http(f"{server_url}/api/health", procs)
            return
        except RuntimeError:
            if retried or not ntrip_port_taken(procs, env):
                raise
        env["AEROBASE_NTRIP_PORT"] = str(free_port())
        say(
            f"port {NTRIP_PORT} was taken meanwhile: the NTRIP caster takes {env['AEROBASE_NTRIP_PORT']}"
        )
        procs.forget("server")


def ntrip_port_taken(procs: Processes, env: dict[str, str]) -> bool:
    """The server exited because its caster could not bind 2101."""
    server = dict(procs.children).get("server")
    if server is None or server.poll() is None or env["AEROBASE_NTRIP_PORT"] != str(NTRIP_PORT):
        return False
    log = (procs.folder / "server.log").read_text(errors="replace")
    return f", {NTRIP_PORT}): address already in use" in log


async def run_mission(
    args: argparse.Namespace,
    procs: Processes,
    folder: Path,
    env: dict[str, str],
    passwords: dict[str, str],
) -> tuple[str, dict[str, int]]:
    """Everything up to the end of the one run; returns its outcome and the world's ports."""
    server_url = f"http://127.0.0.1:{args.port}"
    ports = await start_world_and_server(args, procs, env, server_url)
    async with httpx.AsyncClient(base_url=server_url, timeout=30) as c:
        fleet = await register(c, passwords)
        autopilot = args.autopilot or f"tcp:127.0.0.1:{ports['mavlink']}"
        write_daemon_files(
            folder,
            ports,
            args.speed,
            passwords["asset"],
            fleet.base,
            fleet.uav,
            autopilot,
            args.precland_steering,
        )
        say("starting the landing-base daemon and the UAV agent")
        procs.start("base-station", ["base-station", "--config", str(folder / "base.toml")], env)
        procs.start("agent", ["agent", "--config", str(folder / "agent.toml")], env)
        lat, lon = await wait_ready(c, fleet, procs)
        await wait_uav_available(c, fleet, procs)
        await announce_video(c, fleet, server_url)
        await schedule_survey(c, fleet, lat, lon)
        outcome = await watch(server_url, fleet, procs)
        await report_run(c, fleet, outcome)
    return outcome, ports


def banner(
    args: argparse.Namespace, folder: Path, ports: dict[str, int], pw: dict[str, str]
) -> str:
    """Where everything is, for the one who keeps the demo serving."""
    server_url = f"http://127.0.0.1:{args.port}"
    return f"""
Aerobase is running on {server_url}  (operator console: {server_url}/, API docs: {server_url}/api/docs)
  operator login : {OPS_EMAIL} / {pw["ops"]}
  superuser      : {ROOT_EMAIL} / {pw["root"]}
  asset password : in {folder / "asset-password"}
  simulator      : control API http://127.0.0.1:{ports["control"]} (faults, weather, ground truth)
  NTRIP caster   : ntrip://127.0.0.1:{ports["ntrip"]}/base-porto-1 (the operator login; v1 and v2)
Press Ctrl-C to stop everything."""


async def demo(
    args: argparse.Namespace, folder: Path, env: dict[str, str], pw: dict[str, str]
) -> int:
    """Run the demo; returns the exit status."""
    procs = Processes(folder)
    try:
        outcome, ports = await run_mission(args, procs, folder, env, pw)
        if args.once:
            return 0 if outcome == "completed" else 1
        ports = {**ports, "ntrip": int(env["AEROBASE_NTRIP_PORT"])}
        print(banner(args, folder, ports, pw), flush=True)
        await serve_until_stopped(procs)
        return 0
    except RuntimeError as err:
        say(f"failed: {err}")
        return 1
    finally:
        say("stopping every process")
        procs.stop()


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of `aerobase demo`."""
    parser = argparse.ArgumentParser(prog="aerobase demo", description=__doc__.splitlines()[0])
    parser.add_argument("--once", action="store_true", help="exit after the run: 0 if it completed")
    parser.add_argument("--port", type=int, default=8000)
    parser.add_argument(
        "--speed",
        type=float,
        default=2.0,
        help="simulated seconds per wall second (at 5x a busy machine's delays, five times "
        "longer in the world, made the agent's landing steering overshoot off the pad)",
    )
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--dir", default="var/demo", help="where files, logs and the database go")
    parser.add_argument(
        "--autopilot",
        metavar="URL",
        help="fly this external autopilot (the agent's MAVLink URL, e.g. tcp:127.0.0.1:5760) "
        "instead of the simulated one; needs --autopilot-watch",
    )
    parser.add_argument(
        "--autopilot-watch",
        metavar="URL",
        help="a second, read-only MAVLink connection to the same autopilot (e.g. "
        "tcp:127.0.0.1:5762) through which the world follows it",
    )
    parser.add_argument(
        "--follow-timeout",
        type=float,
        default=120.0,
        help="seconds to wait for the external autopilot's home (HOME_POSITION)",
    )
    parser.add_argument(
        "--precland-steering",
        choices=("agent", "autopilot"),
        default="agent",
        help="who steers the precision landing's descent: the agent's own filter (a "
        "LANDING_TARGET every control step) or the autopilot's precision landing fed the "
        "agent's detections (ArduPilot PLND_TYPE=1)",
    )
    args = parser.parse_args(argv)
    if bool(args.autopilot) != bool(args.autopilot_watch):
        parser.error("--autopilot and --autopilot-watch go together")
    if args.autopilot_watch:
        try:
            parse_url(args.autopilot_watch)
        except BadUrl as err:
            parser.error(f"--autopilot-watch: {err}")
    try:
        folder, env, passwords = prepare(args)
    except (OSError, RuntimeError) as err:
        say(f"failed: {err}")
        return 1
    return asyncio.run(demo(args, folder, env, passwords))
