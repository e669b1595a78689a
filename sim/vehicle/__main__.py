"""Serve one simulated autopilot on its own, on the stand-in always-open pad.

    python -m sim.vehicle [--speed 1] [--seed 0] [--tcp-port 5760] [--udp-port 14550]
                          [--control-port 8091] [--host 127.0.0.1]
                          [--autopilot-profile ardupilot-4|ardupilot-3.7] [--boot-s S]
                          [--no-message-interval] [--silent-message-interval]
                          [--no-extended-sys-state]
                          [--keep-params] [--streams-at-boot all|heartbeat]
                          [--plnd ardupilot|simple] [--uptime-s S]

Without a profile it keeps the simulator's defaults (ArduPilot 4.x habits, every stream on, no
boot delay); a profile brings that release's habits (sim/vehicle/habits.py), 35-40 s of booting
included; each option after it overrides one habit.

Connect with ``tcp:127.0.0.1:5760`` or ``udpout:127.0.0.1:14550`` (send first). The control
routes (truth, faults) are served on --control-port under /vehicle; 0 disables them.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import logging
from collections.abc import Sequence
from dataclasses import replace

from sim.clock import SimClock
from sim.vehicle.control import vehicle_router
from sim.vehicle.copter import Copter, CopterConfig
from sim.vehicle.habits import PROFILES, Habits, profile
from sim.vehicle.plnd import PlndParams
from sim.vehicle.server import VehicleServer
from sim.vehicle.standalone import OpenPad

log = logging.getLogger(__name__)


def parse_args(argv: Sequence[str] | None) -> argparse.Namespace:
    """The command line."""
    ap = argparse.ArgumentParser(prog="python -m sim.vehicle", description=__doc__.splitlines()[0])
    ap.add_argument("--speed", type=float, default=1.0)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--host", default="127.0.0.1")
    ap.add_argument("--tcp-port", type=int, default=5760)
    ap.add_argument("--udp-port", type=int, default=14550)
    ap.add_argument("--control-port", type=int, default=8091)
    ap.add_argument("--autopilot-profile", choices=sorted(PROFILES), default=None)
    ap.add_argument("--boot-s", type=float, default=None, help="simulated seconds to armable")
    ap.add_argument(
        "--no-message-interval", action="store_true", help="refuse SET_MESSAGE_INTERVAL"
    )
    ap.add_argument("--silent-message-interval", action="store_true", help="never answer it")
    ap.add_argument("--no-extended-sys-state", action="store_true")
    ap.add_argument("--keep-params", action="store_true", help="store params as sent (not packed)")
    ap.add_argument("--streams-at-boot", choices=("all", "heartbeat"), default=None)
    ap.add_argument("--plnd-lag", type=float, default=None, help="PLND_LAG, seconds (0.02-0.25)")
    ap.add_argument(
        "--plnd",
        choices=("ardupilot", "simple"),
        default=None,
        help="precision landing as ArduPilot's PLND (companion backend) or the simulator's own",
    )
    ap.add_argument(
        "--uptime-s",
        type=float,
        default=0.0,
        help="the autopilot's uptime at the start, as if left powered on its base "
        "(time_boot_ms wraps after 4294967.296 s, 49.7 days)",
    )
    args = ap.parse_args(argv)
    if args.uptime_s < 0:
        ap.error("--uptime-s must not be negative")
    return args


def habits_of(args: argparse.Namespace) -> Habits:
    """The habits the command line asks for: a profile (or the defaults), then each override."""
    over: dict[str, object] = {}
    if args.boot_s is not None:
        over["boot_s"] = args.boot_s
    if args.no_message_interval:
        over["message_interval"] = False
    if args.silent_message_interval:
        over["message_interval_silent"] = True
    if args.no_extended_sys_state:
        over["extended_sys_state"] = False
    if args.keep_params:
        over["ardupilot_storage"] = False
    if args.streams_at_boot:
        over["streams_at_boot"] = args.streams_at_boot
    if args.plnd == "simple":
        over["plnd"] = None
    elif args.plnd == "ardupilot":
        over["plnd"] = PlndParams()
    habits = profile(args.autopilot_profile, **over) if args.autopilot_profile else Habits(**over)  # type: ignore[arg-type]
    if args.plnd_lag is not None and habits.plnd is not None:
        lag = min(max(args.plnd_lag, 0.02), 0.25)  # AC_PrecLand::init constrains it so
        habits = replace(habits, plnd=replace(habits.plnd, lag_s=lag))
    return habits


def setup(args: argparse.Namespace) -> VehicleServer:
    """Build the vehicle server (nothing bound yet)."""
    config = CopterConfig(seed=args.seed, habits=habits_of(args), powered_s=args.uptime_s)
    copter = Copter(OpenPad(), config)
    return VehicleServer(
        copter, SimClock(args.speed), host=args.host, tcp_port=args.tcp_port, udp_port=args.udp_port
    )


async def run(server: VehicleServer, control_port: int, ports: str | None = None) -> None:
    """Serve until cancelled; the start line names `ports` (default: its TCP and UDP ports)."""
    await server.start()
    log.info("autopilot habits: %s", server.copter.config.habits)
    ports = ports or f"tcp:{server.host}:{server.tcp_port} udp:{server.udp_port}"
    print(f"simulated autopilot: MAVLink {ports}", flush=True)
    try:
        if control_port:
            import uvicorn
            from fastapi import FastAPI

            app = FastAPI(title="simulated autopilot")
            app.include_router(vehicle_router(server))
            config = uvicorn.Config(app, host=server.host, port=control_port, log_level="warning")
            await uvicorn.Server(config).serve()
        else:
            await asyncio.Event().wait()
    finally:
        await server.close()


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point."""
    logging.basicConfig(level=logging.INFO)
    args = parse_args(argv)
    with contextlib.suppress(KeyboardInterrupt):
        asyncio.run(run(setup(args), args.control_port))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
