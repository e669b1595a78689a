"""The vehicle as a part of the simulated world (`sim.world.WorldPart`): same base, wind and clock.

    world.add_part(VehiclePart())        # before world.start()

MAVLink is served on `world.config.mavlink_port` for TCP and the same number for UDP (0: the
OS picks each); the bound ports land in `world.ports["mavlink_tcp"]` / `["mavlink_udp"]`.
The world's loop steps the physics; the control routes mount under /vehicle.
"""

from __future__ import annotations

from typing import Any

from sim.vehicle.control import vehicle_router
from sim.vehicle.copter import Copter, CopterConfig
from sim.vehicle.server import VehicleServer


class VehiclePart:
    """Plugs one simulated autopilot into a `sim.world.World`."""

    name = "vehicle"

    def __init__(self, config: CopterConfig | None = None) -> None:
        self.config = config
        self.server: VehicleServer | None = None

    async def start(self, world: Any) -> None:
        """Create the copter on the world's base and serve MAVLink."""
        cfg = self.config or CopterConfig(seed=world.config.seed)
        copter = Copter(world.base, cfg)
        port = world.config.mavlink_port
        self.server = VehicleServer(
            copter,
            world.clock,
            host=world.config.host,
            tcp_port=port,
            udp_port=port,
            wind_ne=world.weather.flow_ne,  # the copter adds shear and turbulence
            own_loop=False,
        )
        await self.server.start()
        world.ports["mavlink_tcp"] = self.server.tcp_port
        world.ports["mavlink_udp"] = self.server.udp_port

    async def stop(self) -> None:
        """Close the MAVLink sockets."""
        if self.server is not None:
            await self.server.close()

    def step(self, dt_sim: float) -> None:
        """Advance the vehicle with the world."""
        if self.server is not None:
            self.server.step(dt_sim)

    def routers(self) -> list[Any]:
        """The vehicle's control routes, under /vehicle."""
        if self.server is None:
            return []
        return [vehicle_router(self.server)]
