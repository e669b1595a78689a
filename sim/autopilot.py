"""`aerobase sim autopilot`: the simulated autopilot alone, served like ArduPilot SITL serves its
serial ports — MAVLink over TCP on two ports — to stand in for an external autopilot.

    aerobase sim autopilot [--port 5760] [--port2 5762] [--speed 1] [--seed 0] [--host 127.0.0.1]
                           [--home LAT,LON,ALT] [--control-port 0]

Both ports take any number of clients, each with its own stream rates (a link per connection, as
ArduPilot keeps rates per channel): the agent flies it on the first (``tcp:HOST:5760``) and the
world follows it read-only on the second (``aerobase sim world --follow tcp:HOST:5762``). The
vehicle starts landed at `--home` on an always-open pad (`sim.vehicle.standalone.OpenPad`): the
base it lands on is the one the following world builds at its home. `--control-port` serves the
vehicle's control routes (truth, faults) under /vehicle; 0 serves none. Prints one line,
``simulated autopilot: MAVLink tcp:HOST:PORT tcp:HOST:PORT2``, once both ports listen.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import logging
from collections.abc import Sequence
from typing import Any

from sim.clock import SimClock
from sim.vehicle.copter import Copter, CopterConfig
from sim.vehicle.server import VehicleServer
from sim.vehicle.standalone import DEFAULT_PAD, OpenPad

log = logging.getLogger(__name__)


class TwoPortServer(VehicleServer):
    """A `VehicleServer` listening for TCP clients on a second port too (SITL's SERIAL1)."""

    def __init__(self, *args: Any, tcp_port2: int = 0, **kw: Any) -> None:
        super().__init__(*args, **kw)
        self._want_tcp2 = tcp_port2
        self.tcp_port2 = 0
        self._tcp_server2: asyncio.Server | None = None

    async def start(self) -> None:
        """Both TCP ports (and the UDP one) listen; the simulation runs."""
        await super().start()
        self._tcp_server2 = await asyncio.start_server(self._tcp_client, self.host, self._want_tcp2)
        self.tcp_port2 = self._tcp_server2.sockets[0].getsockname()[1]

    async def close(self) -> None:
        """Close both TCP ports and everything `VehicleServer.close` closes."""
        if self._tcp_server2 is not None:
            self._tcp_server2.close()
        await super().close()


def _home(text: str) -> tuple[float, float, float]:
    try:
        lat, lon, alt = (float(v) for v in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not LAT,LON,ALT") from None
    if not (-90 <= lat <= 90 and -180 <= lon <= 180):
        raise argparse.ArgumentTypeError(f"{text!r}: latitude or longitude out of range")
    return lat, lon, alt


def parse_args(argv: Sequence[str] | None) -> argparse.Namespace:
    """The command line."""
    ap = argparse.ArgumentParser(prog="aerobase sim autopilot", description=__doc__.splitlines()[0])
    ap.add_argument("--speed", type=float, default=1.0, help="simulated seconds per wall second")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--host", default="127.0.0.1")
    ap.add_argument("--port", type=int, default=5760, help="first MAVLink TCP port (the agent's)")
    ap.add_argument("--port2", type=int, default=5762, help="second MAVLink TCP port (a watcher's)")
    ap.add_argument("--home", type=_home, default=DEFAULT_PAD, help="LAT,LON,ALT (m MSL)")
    ap.add_argument("--control-port", type=int, default=0, help="HTTP control routes; 0: none")
    a = ap.parse_args(argv)
    if a.speed <= 0:
        ap.error("--speed must be positive")
    return a


def setup(args: argparse.Namespace) -> TwoPortServer:
    """The vehicle server, nothing bound yet."""
    copter = Copter(OpenPad(pad_geodetic=args.home), CopterConfig(seed=args.seed))
    return TwoPortServer(
        copter, SimClock(args.speed), host=args.host, tcp_port=args.port, tcp_port2=args.port2
    )


async def serve(server: TwoPortServer, control_port: int) -> None:
    """Serve until cancelled."""
    await server.start()
    h = server.host
    print(
        f"simulated autopilot: MAVLink tcp:{h}:{server.tcp_port} tcp:{h}:{server.tcp_port2}",
        flush=True,
    )
    try:
        if control_port:
            import uvicorn
            from fastapi import FastAPI

            from sim.vehicle.control import vehicle_router

            app = FastAPI(title="simulated autopilot")
            app.include_router(vehicle_router(server))
            config = uvicorn.Config(app, host=h, port=control_port, log_level="warning")
            await uvicorn.Server(config).serve()
        else:
            await asyncio.Event().wait()
    finally:
        await server.close()


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of `aerobase sim autopilot`."""
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(levelname)s %(name)s %(message)s")
    args = parse_args(argv)
    try:
        with contextlib.suppress(KeyboardInterrupt):
            asyncio.run(serve(setup(args), args.control_port))
    except OSError as err:
        print(f"aerobase sim autopilot: {err}", flush=True)
        return 1
    return 0
