"""The autopilot adapter's typed errors.

AutopilotError
 ├── AutopilotTimeout   no answer within the deadline, retries included
 ├── CommandRejected    COMMAND_ACK with a result other than ACCEPTED (carries the code)
 ├── LinkLost           no HEARTBEAT from the autopilot for the link timeout
 └── MissionError       a mission transfer failed at an item (index in the caller's list)
      └── InvalidMissionItem   refused before sending: malformed or out of range
"""

from __future__ import annotations

MAV_RESULT_NAMES = {
    0: "ACCEPTED", 1: "TEMPORARILY_REJECTED", 2: "DENIED", 3: "UNSUPPORTED", 4: "FAILED",
    5: "IN_PROGRESS", 6: "CANCELLED", 7: "COMMAND_LONG_ONLY", 8: "COMMAND_INT_ONLY",
    9: "COMMAND_UNSUPPORTED_MAV_FRAME",
}  # fmt: skip

MAV_MISSION_RESULT_NAMES = {
    0: "MAV_MISSION_ACCEPTED", 1: "MAV_MISSION_ERROR", 2: "MAV_MISSION_UNSUPPORTED_FRAME",
    3: "MAV_MISSION_UNSUPPORTED", 4: "MAV_MISSION_NO_SPACE", 5: "MAV_MISSION_INVALID",
    6: "MAV_MISSION_INVALID_PARAM1", 7: "MAV_MISSION_INVALID_PARAM2",
    8: "MAV_MISSION_INVALID_PARAM3", 9: "MAV_MISSION_INVALID_PARAM4",
    10: "MAV_MISSION_INVALID_PARAM5_X", 11: "MAV_MISSION_INVALID_PARAM6_Y",
    12: "MAV_MISSION_INVALID_PARAM7", 13: "MAV_MISSION_INVALID_SEQUENCE",
    14: "MAV_MISSION_DENIED", 15: "MAV_MISSION_OPERATION_CANCELLED",
}  # fmt: skip


class AutopilotError(Exception):
    """Base of every error the autopilot adapter raises."""


class AutopilotTimeout(AutopilotError):
    """The autopilot did not answer in time (after every retry)."""


class LinkLost(AutopilotError):
    """The autopilot link is down (no HEARTBEAT for the link timeout)."""


class CommandRejected(AutopilotError):
    """The autopilot answered a command with a MAV_RESULT other than ACCEPTED."""

    def __init__(self, command: int, result: int, detail: str = "") -> None:
        self.command = command
        self.result = result
        self.result_name = MAV_RESULT_NAMES.get(result, str(result))
        self.detail = detail
        extra = f": {detail}" if detail else ""
        super().__init__(f"command {command} rejected: {self.result_name}{extra}")


class MissionError(AutopilotError):
    """A mission transfer failed; `index` is the item's index in the caller's list (None: whole mission)."""

    def __init__(self, index: int | None, reason: str) -> None:
        self.index = index
        self.reason = reason
        where = "mission" if index is None else f"mission item {index}"
        super().__init__(f"{where}: {reason}")


class InvalidMissionItem(MissionError):
    """A mission item is malformed or out of range; nothing was sent."""
