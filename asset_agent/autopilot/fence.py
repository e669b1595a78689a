"""The fence and rally points of the autopilot: upload with read-back, and enabling the fence."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from asset_agent.autopilot import mission, params
from asset_agent.autopilot.items import MissionItem

if TYPE_CHECKING:
    from asset_agent.autopilot.client import Autopilot


class FenceMixin:
    """Fence and rally methods of `Autopilot`."""

    def _ap(self) -> Autopilot:
        return self  # type: ignore[return-value]

    async def upload_fence(self, fence: list[MissionItem], rally: list[MissionItem]) -> None:
        """Upload the fence (MAV_MISSION_TYPE_FENCE) and the rally points (MAV_MISSION_TYPE_RALLY),
        each read back and compared as a mission is; an empty list clears what was there."""
        ap = self._ap()
        await mission.upload(ap, fence, mission_type=mission.MAV_MISSION_TYPE_FENCE)
        await mission.upload(ap, rally, mission_type=mission.MAV_MISSION_TYPE_RALLY)

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
