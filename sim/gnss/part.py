"""The GNSS base receiver as a part of the simulated world (`world.add_part(GnssPart())`)."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from sim.gnss.control import gnss_router
from sim.gnss.receiver import GnssReceiver
from sim.gnss.station import GnssConfig

if TYPE_CHECKING:
    from sim.world import World


class GnssPart:
    """Serves the base receiver on `world.config.gnss_port` with the world's clock and seed.

    Unless a config is given, the antenna reference point is the landing pad's position
    (`world.base.pad_geodetic`) raised by `antenna_height_m`.
    """

    name = "gnss"

    def __init__(self, config: GnssConfig | None = None, antenna_height_m: float = 0.0) -> None:
        self._config = config
        self._antenna_height_m = antenna_height_m
        self.receiver: GnssReceiver | None = None

    async def start(self, world: World) -> None:
        """Start streaming on the world's GNSS port; records `world.ports["gnss"]`."""
        config = self._config
        if config is None:
            lat, lon, height = world.base.pad_geodetic
            config = GnssConfig(
                latitude=lat,
                longitude=lon,
                height_m=height + self._antenna_height_m,
                seed=world.config.seed,
            )
        self.receiver = GnssReceiver(config, world.clock)
        await self.receiver.start(world.config.host, world.config.gnss_port)
        world.ports["gnss"] = self.receiver.port

    async def stop(self) -> None:
        """Stop the receiver."""
        if self.receiver is not None:
            await self.receiver.stop()

    def step(self, dt_sim: float) -> None:
        """Nothing to integrate: the receiver keeps its own epoch timing on the world clock."""

    def routers(self) -> list[Any]:
        """The receiver's fault switches and status under /gnss on the control interface."""
        return [gnss_router(self.receiver)] if self.receiver is not None else []
