"""Serve one simulated autopilot on its own, on the stand-in always-open pad.

    python -m sim.vehicle [--speed 1] [--seed 0] [--tcp-port 5760] [--udp-port 14550]
                          [--control-port 8091] [--host 127.0.0.1]

Connect with ``tcp:127.0.0.1:5760`` or ``udpout:127.0.0.1:14550`` (send first). The control
routes (truth, faults) are served on --control-port under /vehicle; 0 disables them.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import logging
from collections.abc import Sequence

from sim.clock import SimClock
from sim.vehicle.control import vehicle_router
from sim.vehicle.copter import Copter, CopterConfig
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
    return ap.parse_args(argv)


def setup(args: argparse.Namespace) -> VehicleServer:
    """Build the vehicle server (nothing bound yet)."""
    copter = Copter(OpenPad(), CopterConfig(seed=args.seed))
    return VehicleServer(
        copter, SimClock(args.speed), host=args.host, tcp_port=args.tcp_port, udp_port=args.udp_port
    )


async def run(server: VehicleServer, control_port: int) -> None:
    """Serve until cancelled."""
    await server.start()
    print(
        f"simulated autopilot: MAVLink tcp:{server.host}:{server.tcp_port} udp:{server.udp_port}",
        flush=True,
    )
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
