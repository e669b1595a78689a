"""Pure autopilot side of the MAVLink mission protocol: item validation, upload and download.

Upload, as ArduPilot does it: MISSION_COUNT starts it, the autopilot requests each item with
MISSION_REQUEST_INT, re-requests after `resend_s` (1 s) without an answer and cancels the
transfer with MAV_MISSION_OPERATION_CANCELLED after `timeout_s` (8 s) of silence. An item that
fails validation ends the upload with its MAV_MISSION_RESULT. Item 0 is home: its content is
ignored on upload and replaced by the current home on download.

The state machine returns actions, never sends: ("request", seq) or ("ack", result).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

# MAV_MISSION_RESULT
ACCEPTED, ERROR, UNSUPPORTED_FRAME, UNSUPPORTED, NO_SPACE, INVALID = 0, 1, 2, 3, 4, 5
INVALID_PARAM1, INVALID_PARAM2, INVALID_PARAM3, INVALID_PARAM4 = 6, 7, 8, 9
INVALID_PARAM5_X, INVALID_PARAM6_Y, INVALID_PARAM7 = 10, 11, 12
INVALID_SEQUENCE, DENIED, OPERATION_CANCELLED = 13, 14, 15

# MAV_CMD
NAV_WAYPOINT, NAV_LOITER_UNLIM, NAV_LOITER_TURNS, NAV_LOITER_TIME = 16, 17, 18, 19
NAV_RETURN_TO_LAUNCH, NAV_LAND, NAV_TAKEOFF, NAV_SPLINE_WAYPOINT, NAV_DELAY = 20, 21, 22, 82, 93
DO_JUMP, DO_CHANGE_SPEED = 177, 178
NAV_COMMANDS = (
    NAV_WAYPOINT, NAV_LOITER_UNLIM, NAV_LOITER_TURNS, NAV_LOITER_TIME, NAV_RETURN_TO_LAUNCH,
    NAV_LAND, NAV_TAKEOFF, NAV_SPLINE_WAYPOINT, NAV_DELAY,
)  # fmt: skip
POSITIONAL_NAV = tuple(c for c in NAV_COMMANDS if c not in (NAV_RETURN_TO_LAUNCH, NAV_DELAY))
# camera, gimbal, relay, servo, ROI, yaw and delay commands: stored and stepped over in flight
PASSIVE_COMMANDS = (112, 115, 181, 183, 195, 197, 201, 203, 205, 206, 530, 2000, 2001, 2500, 2501)
SUPPORTED_COMMANDS = (*NAV_COMMANDS, DO_JUMP, DO_CHANGE_SPEED, *PASSIVE_COMMANDS)

# MAV_FRAME
FRAME_GLOBAL, FRAME_MISSION, FRAME_GLOBAL_RELATIVE_ALT = 0, 2, 3
FRAME_GLOBAL_INT, FRAME_GLOBAL_RELATIVE_ALT_INT = 5, 6
GLOBAL_FRAMES = (
    FRAME_GLOBAL,
    FRAME_GLOBAL_RELATIVE_ALT,
    FRAME_GLOBAL_INT,
    FRAME_GLOBAL_RELATIVE_ALT_INT,
)
RELATIVE_FRAMES = (FRAME_GLOBAL_RELATIVE_ALT, FRAME_GLOBAL_RELATIVE_ALT_INT)

MAX_ITEMS = 718  # what a 4 KiB-storage ArduPilot board holds
MAX_ALT_M = 10_000.0
MAX_SPEED_MPS = 50.0


@dataclass(frozen=True)
class Item:
    """One stored mission item, in MISSION_ITEM_INT terms (x, y = degrees * 1e7)."""

    seq: int
    frame: int
    command: int
    param1: float = 0.0
    param2: float = 0.0
    param3: float = 0.0
    param4: float = 0.0
    x: int = 0
    y: int = 0
    z: float = 0.0
    autocontinue: int = 1

    @property
    def lat(self) -> float:
        """Latitude in degrees."""
        return self.x / 1e7

    @property
    def lon(self) -> float:
        """Longitude in degrees."""
        return self.y / 1e7


def validate(item: Item) -> int:
    """The MAV_MISSION_RESULT for storing `item` (ACCEPTED when it is fine)."""
    if item.command not in SUPPORTED_COMMANDS:
        return UNSUPPORTED
    params = (item.param1, item.param2, item.param3, item.param4)
    for code, value in zip(
        (INVALID_PARAM1, INVALID_PARAM2, INVALID_PARAM3, INVALID_PARAM4), params, strict=True
    ):
        if math.isinf(value):  # NaN is MAVLink's "unchanged"
            return code
    if not math.isfinite(item.z):
        return INVALID_PARAM7
    if item.command == DO_CHANGE_SPEED:
        if not 0.0 < item.param2 <= MAX_SPEED_MPS:
            return INVALID_PARAM2
        return ACCEPTED
    if item.command == DO_JUMP:
        return ACCEPTED if item.param1 >= 1 else INVALID_PARAM1
    if item.command not in POSITIONAL_NAV:
        return ACCEPTED  # no position: any frame will do
    if item.frame not in GLOBAL_FRAMES:
        return UNSUPPORTED_FRAME
    if not -90e7 <= item.x <= 90e7:
        return INVALID_PARAM5_X
    if not -180e7 <= item.y <= 180e7:
        return INVALID_PARAM6_Y
    if not -1000.0 <= item.z <= MAX_ALT_M:
        return INVALID_PARAM7
    if item.command in (NAV_WAYPOINT, NAV_LOITER_TIME, NAV_LOITER_TURNS) and item.param1 < 0:
        return INVALID_PARAM1
    return ACCEPTED


class Upload:
    """One mission upload in progress, from MISSION_COUNT to the final MISSION_ACK."""

    def __init__(
        self, count: int, now: float, resend_s: float = 1.0, timeout_s: float = 8.0
    ) -> None:
        self.count = count
        self.items: list[Item] = []
        self.resend_s = resend_s
        self.timeout_s = timeout_s
        self._last_rx = now
        self._last_request = now
        self.done = False
        self.result: int | None = None

    def start(self) -> tuple[str, int]:
        """The first action: request item 0, or reject the count."""
        if self.count > MAX_ITEMS:
            return self._finish(NO_SPACE)
        if self.count == 0:
            return self._finish(ACCEPTED)
        return ("request", 0)

    @property
    def expected(self) -> int:
        """The sequence number the autopilot is waiting for."""
        return len(self.items)

    def on_item(self, item: Item, now: float) -> tuple[str, int] | None:
        """An item arrived; the next action, or None for a duplicate of an earlier item."""
        if item.seq < self.expected:
            return None  # a retry of something we already have: ignore, as ArduPilot does
        if item.seq > self.expected:
            return ("request", self.expected)
        self._last_rx = self._last_request = now
        result = ACCEPTED if item.seq == 0 else validate(item)
        if result != ACCEPTED:
            return self._finish(result)
        self.items.append(item)
        if len(self.items) == self.count:
            return self._finish(ACCEPTED)
        return ("request", self.expected)

    def on_count_again(self, now: float) -> tuple[str, int]:
        """The same MISSION_COUNT again (the ground's retry): re-request what we wait for."""
        self._last_rx = self._last_request = now
        return ("request", self.expected)

    def update(self, now: float) -> tuple[str, int] | None:
        """Time passes: re-request or cancel; None when nothing is due."""
        if self.done:
            return None
        if now - self._last_rx > self.timeout_s:
            return self._finish(OPERATION_CANCELLED)
        if now - self._last_request > self.resend_s:
            self._last_request = now
            return ("request", self.expected)
        return None

    def _finish(self, result: int) -> tuple[str, int]:
        self.done = True
        self.result = result
        return ("ack", result)


def nav_index_after(items: list[Item], seq: int) -> int | None:
    """The first item at or after `seq` (skipping home), or None past the end."""
    seq = max(seq, 1)
    return seq if seq < len(items) else None


def starts_with_takeoff(items: list[Item]) -> bool:
    """True when the first navigation command after home is a takeoff (AUTO from the ground)."""
    for item in items[1:]:
        if item.command in NAV_COMMANDS:
            return item.command == NAV_TAKEOFF
    return False


# how long each nav item holds once there (LOITER_TURNS: 10 s a turn)
HOLD_S = {
    NAV_WAYPOINT: lambda it: max(it.param1, 0.0),
    NAV_SPLINE_WAYPOINT: lambda it: max(it.param1, 0.0),
    NAV_LOITER_TIME: lambda it: max(it.param1, 0.0),
    NAV_LOITER_TURNS: lambda it: 10.0 * max(it.param1, 0.0),
    NAV_DELAY: lambda it: max(it.param1, 0.0),
}

CMD_NAMES = {
    NAV_WAYPOINT: "WP", NAV_LOITER_TIME: "LoitTime", NAV_RETURN_TO_LAUNCH: "RTL",
    NAV_LAND: "Land", NAV_TAKEOFF: "Takeoff", DO_CHANGE_SPEED: "ChangeSpeed",
    DO_JUMP: "Jump", NAV_LOITER_UNLIM: "LoitUnlim", NAV_LOITER_TURNS: "LoitTurns",
    NAV_SPLINE_WAYPOINT: "SplineWP", NAV_DELAY: "Delay",
}  # fmt: skip
