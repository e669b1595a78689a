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

# every MAV_MISSION_RESULT as a sentence a person can act on
MISSION_RESULT_TEXT = {
    0: "the mission was accepted",
    1: "the autopilot reported a generic mission error",
    2: "the coordinate frame of the item is not supported by the autopilot",
    3: "the command of the item is not supported by the autopilot",
    4: "the mission has more items than the autopilot can store",
    5: "one of the item's parameters is invalid",
    6: "param1 of the item is out of range for the autopilot",
    7: "param2 of the item is out of range for the autopilot",
    8: "param3 of the item is out of range for the autopilot",
    9: "param4 of the item is out of range for the autopilot",
    10: "the item's latitude (x) is out of range for the autopilot",
    11: "the item's longitude (y) is out of range for the autopilot",
    12: "the item's altitude (param7 / z) is out of range for the autopilot",
    13: "the item arrived out of sequence",
    14: "the autopilot is not accepting missions now (busy with another transfer, or armed)",
    15: "the autopilot cancelled the transfer (it waited too long for an item)",
}


def mission_result_text(code: int) -> str:
    """MAV_MISSION_RESULT -> "MAV_MISSION_INVALID_PARAM4: param4 of the item is ..."."""
    name = MAV_MISSION_RESULT_NAMES.get(code, f"MAV_MISSION_RESULT {code}")
    return f"{name}: {MISSION_RESULT_TEXT.get(code, 'a result this agent does not know')}"


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
