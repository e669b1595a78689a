"""The whole simulated world as `aerobase sim world` serves it: base (PLC), GNSS receiver, vehicle.

    world = full_world(WorldConfig(speed=5))   # base + GNSS base receiver + one multirotor
    async with world: ...                       # world.ports has every bound port

The vehicle starts landed on the base's pad; the GNSS receiver's antenna is the pad's position.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
from collections.abc import Sequence

from sim.gnss.part import GnssPart
from sim.vehicle.part import VehiclePart
from sim.world import World, WorldConfig, parse_args, run


def full_world(config: WorldConfig | None = None) -> World:
    """A world with every part plugged in."""
    world = World(config)
    world.add_part(GnssPart())
    world.add_part(VehiclePart())
    return world


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of `aerobase sim world`."""
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(levelname)s %(name)s %(message)s")
    world = full_world(parse_args(argv))
    with contextlib.suppress(KeyboardInterrupt):
        asyncio.run(run(world))
    return 0
