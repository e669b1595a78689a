"""The autopilot adapter: the only code in asset_agent that speaks MAVLink (pymavlink).

Public API: `Autopilot`, `AutopilotConfig`, `Notification`, `UavState`, the mission item
converters (`MissionItem`, `items_from_dicts`, `items_to_dicts`) and the error tree
(`AutopilotError`, `AutopilotTimeout`, `CommandRejected`, `LinkLost`, `MissionError`,
`InvalidMissionItem`).
"""

from asset_agent.autopilot.client import Autopilot
from asset_agent.autopilot.config import AutopilotConfig
from asset_agent.autopilot.errors import (
    AutopilotError,
    AutopilotTimeout,
    CommandRejected,
    InvalidMissionItem,
    LinkLost,
    MissionError,
)
from asset_agent.autopilot.items import MissionItem, items_from_dicts, items_to_dicts
from asset_agent.autopilot.state import Notification, UavState

__all__ = [
    "Autopilot",
    "AutopilotConfig",
    "AutopilotError",
    "AutopilotTimeout",
    "CommandRejected",
    "InvalidMissionItem",
    "LinkLost",
    "MissionError",
    "MissionItem",
    "Notification",
    "UavState",
    "items_from_dicts",
    "items_to_dicts",
]
