"""`aerobase sim autopilot`: the simulated autopilot alone on two MAVLink TCP ports, as SITL serves.

It stands in for an external autopilot: ArduPilot SITL serves SERIAL0 and SERIAL1 as TCP ports
5760 and 5762, and so does this.

    aerobase sim autopilot [--tcp-port 5760] [--tcp-port2 5762] [--home LAT,LON,ALT]
                           [every other flag of python -m sim.vehicle: --speed, --seed, --host,
                            --udp-port, --control-port, the autopilot's habits]

Both ports take any number of clients, each with its own stream rates (a link per connection, as
ArduPilot keeps rates per channel): the agent flies it on the first (``tcp:HOST:5760``) and the
world follows it read-only on the second (``aerobase sim world --follow tcp:HOST:5762``). The
vehicle is built as ``python -m sim.vehicle`` builds it and starts landed at `--home` on an
always-open pad (`sim.vehicle.standalone.OpenPad`): the base it lands on is the one the following
world builds at its home. Prints ``simulated autopilot: MAVLink tcp:HOST:PORT tcp:HOST:PORT2``
once both ports listen.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import logging
from collections.abc import Sequence
from typing import Any

from sim.vehicle.__main__ import parse_args as vehicle_args
from sim.vehicle.__main__ import run as vehicle_run
from sim.vehicle.__main__ import setup as vehicle_setup
from sim.vehicle.copter import Copter
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
    """`--tcp-port2` and `--home` here; every other flag is `python -m sim.vehicle`'s."""
    ap = argparse.ArgumentParser(
        prog="aerobase sim autopilot",
        allow_abbrev=False,  # --tcp-port is sim.vehicle's, not an abbreviation of --tcp-port2
        description=__doc__.splitlines()[0],
        epilog="Every other flag is python -m sim.vehicle's (--speed, --seed, --host, --tcp-port, "
        "--udp-port, --control-port and the autopilot's habits); see python -m sim.vehicle -h.",
    )
    ap.add_argument("--tcp-port2", type=int, default=5762, help="second MAVLink TCP port")
    ap.add_argument("--home", type=_home, default=DEFAULT_PAD, help="LAT,LON,ALT (m MSL)")
    ours, rest = ap.parse_known_args(argv)
    args = vehicle_args(rest)
    if args.speed <= 0:
        ap.error("--speed must be positive")
    args.tcp_port2, args.home = ours.tcp_port2, ours.home
    return args


def setup(args: argparse.Namespace) -> TwoPortServer:
    """The vehicle server as `python -m sim.vehicle` builds it (habits included), at `args.home`,
    listening on a second TCP port too; nothing bound yet."""
    single = vehicle_setup(args)
    copter = Copter(OpenPad(pad_geodetic=args.home), single.copter.config)
    return TwoPortServer(
        copter,
        single.clock,
        host=args.host,
        tcp_port=args.tcp_port,
        udp_port=args.udp_port,
        tcp_port2=args.tcp_port2,
    )


async def serve(server: TwoPortServer, control_port: int) -> None:
    """Serve until cancelled: `python -m sim.vehicle`'s loop, announcing both TCP ports."""
    h = server.host
    await vehicle_run(server, control_port, f"tcp:{h}:{server.tcp_port} tcp:{h}:{server.tcp_port2}")


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
