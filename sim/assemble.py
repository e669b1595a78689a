"""The whole simulated world as `aerobase sim world` serves it: base (PLC), GNSS receiver, vehicle,
and the vehicle's precision-landing sensors (downward camera, IR beacon).

    world = full_world(WorldConfig(speed=5))   # base + GNSS base receiver + one multirotor
    async with world: ...                       # world.ports has every bound port

The vehicle starts landed on the base's pad; the GNSS receiver's antenna is the pad's position.
The camera (TCP, `world.ports["camera"]`) and the IR sensor (UDP, `world.ports["ir"]`) see the pad
from the vehicle's true pose: north/east of the pad centre, the camera `SEAT_HEIGHT` above the
vehicle's ground contact, its true attitude; timestamps are the world clock's seconds.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
from collections.abc import Sequence

from sim.camera.part import CameraPart
from sim.gnss.part import GnssPart
from sim.ir import IrPart
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


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of `aerobase sim world`."""
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(levelname)s %(name)s %(message)s")
    world = full_world(parse_args(argv))
    with contextlib.suppress(KeyboardInterrupt):
        asyncio.run(run(world))
    return 0
