"""The fence and rally points of the autopilot: upload with read-back, and enabling the fence."""

from __future__ import annotations

import asyncio
from typing import TYPE_CHECKING, Any

from asset_agent.autopilot import mission, params
from asset_agent.autopilot.errors import AutopilotError, AutopilotTimeout
from asset_agent.autopilot.items import MissionItem

if TYPE_CHECKING:
    from asset_agent.autopilot.client import Autopilot


CMD_REQUEST_AUTOPILOT_CAPABILITIES = 520
CAP_MISSION_FENCE, CAP_MISSION_RALLY = 16384, 32768  # MAV_PROTOCOL_CAPABILITY_MISSION_*


class FenceUnsupported(AutopilotError):
    """The autopilot does not take a fence or rally points over the mission protocol."""


class FenceMixin:
    """Fence and rally methods of `Autopilot`."""

    def _ap(self) -> Autopilot:
        return self  # type: ignore[return-value]

    async def capabilities(self) -> int:
        """AUTOPILOT_VERSION.capabilities (MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES, which every
        ArduPilot since 3.x answers; MAV_CMD_REQUEST_MESSAGE came later)."""
        ap = self._ap()
        with ap.tap(lambda m: m.get_type() == "AUTOPILOT_VERSION") as q:
            await ap.command(CMD_REQUEST_AUTOPILOT_CAPABILITIES, 1)
            try:
                msg = await asyncio.wait_for(q.get(), ap.config.command_timeout_s * 3)
            except TimeoutError:
                raise AutopilotTimeout("no AUTOPILOT_VERSION after its request") from None
        return int(msg.capabilities)

    async def upload_fence(self, fence: list[MissionItem], rally: list[MissionItem]) -> None:
        """Upload the fence (MAV_MISSION_TYPE_FENCE) and the rally points (MAV_MISSION_TYPE_RALLY),
        each read back and compared as a mission is; an empty list clears what was there.

        Only to an autopilot that says it takes them (AUTOPILOT_VERSION): one that does not
        (ArduPilot before 4.0) may read a MISSION_COUNT of another type as a mission upload and
        lose the mission. There an empty fence is skipped; a fence is refused (FenceUnsupported):
        a flight with zones must not leave without its fence on board."""
        ap = self._ap()
        caps = await self.capabilities()
        if not caps & CAP_MISSION_FENCE:
            if fence:
                raise FenceUnsupported(
                    "the autopilot does not take a fence over the mission protocol (no "
                    "MAV_PROTOCOL_CAPABILITY_MISSION_FENCE; ArduPilot 4.0 or later does)"
                )
        else:
            await mission.upload(ap, fence, mission_type=mission.MAV_MISSION_TYPE_FENCE)
        if caps & CAP_MISSION_RALLY:
            await mission.upload(ap, rally, mission_type=mission.MAV_MISSION_TYPE_RALLY)
        elif rally:
            raise FenceUnsupported(
                "the autopilot does not take rally points over the mission protocol (no "
                "MAV_PROTOCOL_CAPABILITY_MISSION_RALLY)"
            )

    async def download_fence(self) -> list[MissionItem]:
        """Read the fence back."""
        return await mission.download(self._ap(), mission_type=mission.MAV_MISSION_TYPE_FENCE)

    async def download_rally(self) -> list[MissionItem]:
        """Read the rally points back."""
        return await mission.download(self._ap(), mission_type=mission.MAV_MISSION_TYPE_RALLY)

    async def enable_fence(self, alt_max_m: float | None) -> dict[str, Any]:
        """Turn the fence on with RTL as its breach action (params.py); the values held."""
        return await params.enable_fence(self._ap(), alt_max_m)

    async def set_param(self, name: str, value: float) -> float:
        """Set one parameter (REAL32); the value the autopilot holds."""
        return await params.set_param(self._ap(), name, value)
