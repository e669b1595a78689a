"""The whole simulated world as `aerobase sim world` serves it: base (PLC), GNSS receiver, vehicle,
and the vehicle's precision-landing sensors (downward camera, IR beacon).

    world = full_world(WorldConfig(speed=5))   # base + GNSS base receiver + one multirotor
    async with world: ...                       # world.ports has every bound port

The vehicle starts landed on the base's pad; the GNSS receiver's antenna is the pad's position.
The camera (TCP, `world.ports["camera"]`) and the IR sensor (UDP, `world.ports["ir"]`) see the pad
from the vehicle's true pose: north/east of the pad centre, the camera `SEAT_HEIGHT` above the
vehicle's ground contact, its true attitude; timestamps are the world clock's seconds.

With `config.follow` (`aerobase sim world --follow URL`) the world simulates no vehicle: it waits for
the external autopilot's home on that read-only MAVLink connection, builds the base there and the
camera and IR sensor see the pad from the pose the autopilot reports (`following_world`, `sim.follow`).
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import sys
from collections.abc import Sequence
from dataclasses import replace

from sim.camera.part import CameraPart
from sim.follow import Follower, FollowerPart
from sim.gnss.part import GnssPart
from sim.ir import IrPart
from sim.mavlink_link import BadUrl
from sim.vehicle.part import VehiclePart
from sim.world import World, WorldConfig, parse_args, run

log = logging.getLogger(__name__)

SEAT_HEIGHT = (
    0.25  # camera height above the pad when the vehicle sits on it (as bench.precland_eval)
)


def vehicle_pose(part: VehiclePart) -> tuple[float, float, float, float, float, float]:
    """(north, east, camera height, roll, pitch, yaw) of the vehicle's truth, relative to the pad."""
    if part.server is None:
        return (0.0, 0.0, SEAT_HEIGHT, 0.0, 0.0, 0.0)
    st = part.server.copter.dyn.state
    n, e, d = st.position
    return (n, e, SEAT_HEIGHT - d, st.roll, st.pitch, st.yaw)


def full_world(config: WorldConfig | None = None) -> World:
    """A world with every part plugged in."""
    world = World(config)
    world.add_part(GnssPart())
    vehicle = VehiclePart()
    world.add_part(vehicle)
    world.add_part(CameraPart(lambda: vehicle_pose(vehicle)))
    world.add_part(IrPart(lambda: vehicle_pose(vehicle)))
    return world


def following_world(config: WorldConfig, follower: Follower) -> World:
    """A world around an external vehicle: base (where `config.base` puts the pad), GNSS receiver,
    and the camera and IR sensor looking from the pose `follower` reports."""
    world = World(config)
    world.add_part(GnssPart())
    part = FollowerPart(follower, SEAT_HEIGHT, speed=config.speed)
    world.add_part(part)
    world.add_part(CameraPart(part.pose))
    world.add_part(IrPart(part.pose))
    return world


class FollowError(RuntimeError):
    """The external vehicle cannot be followed (bad URL, no home)."""


async def build(config: WorldConfig) -> World:
    """The world `config` asks for; following an external vehicle, once its home is known."""
    if not config.follow:
        return full_world(config)
    try:
        follower = Follower(config.follow)
    except BadUrl as err:
        raise FollowError(str(err)) from None
    await follower.start()
    print(f"aerobase sim world: waiting for the home of the vehicle at {config.follow}", flush=True)
    try:
        home = await follower.wait_home(config.follow_timeout_s)
    except TimeoutError:
        await follower.stop()
        raise FollowError(
            f"no HOME_POSITION from {config.follow} within {config.follow_timeout_s:g} s "
            f"({'connected' if follower.link.is_connected else 'never connected'}, "
            f"{follower.link.received_count} messages): is the autopilot running, with a GPS fix?"
        ) from None
    return following_world(replace(config, base=replace(config.base, pad_geodetic=home)), follower)


async def serve(config: WorldConfig) -> None:
    """Build the world and serve it until cancelled."""
    await run(await build(config))


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of `aerobase sim world`."""
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(levelname)s %(name)s %(message)s")
    try:
        with contextlib.suppress(KeyboardInterrupt):
            asyncio.run(serve(parse_args(argv)))
    except FollowError as err:
        print(f"aerobase sim world: {err}", file=sys.stderr)
        return 1
    return 0
