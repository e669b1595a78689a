"""The simulated autopilot's geofence and rally points, as ArduPilot Copter keeps and enforces them.

Storage (AC_PolyFence_loader, MissionItemProtocol_Fence / _Rally): the fence and the rally
points are uploaded with the mission protocol under MAV_MISSION_TYPE_FENCE (1) and
MAV_MISSION_TYPE_RALLY (2); neither has a home item (seq 0 is the first item). A fence is
checked as a whole when its last item arrives (`validate_fence`): a polygon is a run of
consecutive vertices of one type, each carrying the vertex count (at least 3) in param1; a
circle has a positive radius in param1; at most one return point; every position a valid
lat/lon. A refused fence answers MAV_MISSION_ERROR and the stored one is kept. The fence keeps
no altitude (read back as 0); a rally point keeps whole metres.

Enforcement (AC_Fence::check, Copter's fence_check): with FENCE_ENABLE = 1 and the vehicle
armed, the estimated position is breached when it is outside any inclusion polygon or circle,
inside any exclusion polygon or circle (FENCE_TYPE bit 4), or above FENCE_ALT_MAX (bit 1). A new
breach in flight with FENCE_ACTION not 0 (report only) switches to RTL (LAND when RTL cannot be
entered), unless already returning or landing; more than 100 m outside (the give-up distance)
lands where it is. FENCE_STATUS goes out once a second while the fence is enabled.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

from pymavlink.dialects.v20 import ardupilotmega as mavlink

from sim.vehicle import mission as ms
from sim.vehicle.constants import CRITICAL, LAND, RTL
from sim.vehicle.geo import GeoOrigin

MISSION_TYPE_FENCE, MISSION_TYPE_RALLY = 1, 2
RETURN_POINT, VERTEX_INCLUSION, VERTEX_EXCLUSION = 5000, 5001, 5002
CIRCLE_INCLUSION, CIRCLE_EXCLUSION, RALLY_POINT = 5003, 5004, 5100
FENCE_COMMANDS = tuple(range(RETURN_POINT, CIRCLE_EXCLUSION + 1))  # 5000-5004
MAX_FENCE_ITEMS, MAX_RALLY_POINTS = 255, 20  # a small board's fence storage; RALLY_TOTAL's limit
TYPE_ALT_MAX, TYPE_POLYGON = 1, 4
BREACH_NONE, BREACH_MAXALT, BREACH_BOUNDARY = 0, 2, 3
GIVE_UP_DISTANCE_M = 100.0  # AC_FENCE_GIVE_UP_DISTANCE
PARAM_INT8, PARAM_REAL32 = 2, 9
CAP_MISSION_INT, CAP_MAVLINK2, CAP_MISSION_FENCE, CAP_MISSION_RALLY = 4, 8192, 16384, 32768
DEFAULT_PARAMS: dict[str, tuple[float, int]] = {
    "FENCE_ENABLE": (0.0, PARAM_INT8),
    "FENCE_TYPE": (7.0, PARAM_INT8),  # Copter's default: max altitude, circle, polygon
    "FENCE_ACTION": (1.0, PARAM_INT8),
    "FENCE_ALT_MAX": (100.0, PARAM_REAL32),
    "FENCE_MARGIN": (2.0, PARAM_REAL32),
    "DISARM_DELAY": (10.0, PARAM_INT8),  # not the fence's: disarm.py (one store of parameters)
}


def validate_fence(items: Sequence[ms.Item]) -> bool:
    """True when the whole fence is one ArduPilot would store."""
    expecting, left, count, returns = 0, 0, 0, 0
    for it in items:
        if it.command not in FENCE_COMMANDS:
            return False
        if not (-90e7 <= it.x <= 90e7 and -180e7 <= it.y <= 180e7):
            return False
        if it.command in (VERTEX_INCLUSION, VERTEX_EXCLUSION):
            n = int(it.param1)
            if n < 3:
                return False
            if left == 0:
                expecting, left, count = it.command, n, n
            elif it.command != expecting or n != count:
                return False
            left -= 1
            continue
        if left:
            return False  # a polygon's vertices must be consecutive
        if it.command in (CIRCLE_INCLUSION, CIRCLE_EXCLUSION) and not it.param1 > 0:
            return False
        if it.command == RETURN_POINT:
            returns += 1
            if returns > 1:
                return False
    return left == 0


def _inside(p: tuple[float, float], ring: Sequence[tuple[float, float]]) -> bool:
    x, y = p
    inside = False
    for k in range(len(ring)):
        (x1, y1), (x2, y2) = ring[k], ring[(k + 1) % len(ring)]
        if (y1 > y) != (y2 > y) and x < x1 + (y - y1) * (x2 - x1) / (y2 - y1):
            inside = not inside
    return inside


def _distance_to_ring(p: tuple[float, float], ring: Sequence[tuple[float, float]]) -> float:
    best = math.inf
    for k in range(len(ring)):
        (x1, y1), (x2, y2) = ring[k], ring[(k + 1) % len(ring)]
        dx, dy = x2 - x1, y2 - y1
        t = 0.0 if dx == dy == 0 else ((p[0] - x1) * dx + (p[1] - y1) * dy) / (dx * dx + dy * dy)
        t = min(1.0, max(0.0, t))
        best = min(best, math.hypot(p[0] - x1 - t * dx, p[1] - y1 - t * dy))
    return best


@dataclass
class Shapes:
    """A stored fence in local north/east metres around home."""

    inclusion: list[list[tuple[float, float]]] = field(default_factory=list)
    exclusion: list[list[tuple[float, float]]] = field(default_factory=list)
    circles_in: list[tuple[tuple[float, float], float]] = field(default_factory=list)
    circles_out: list[tuple[tuple[float, float], float]] = field(default_factory=list)

    @classmethod
    def of(cls, items: Sequence[ms.Item], origin: GeoOrigin) -> Shapes:
        """The polygons and circles of a validated fence."""
        shapes, ring = cls(), []
        for it in items:
            n, e, _ = origin.to_ned(it.lat, it.lon, origin.alt)
            if it.command in (VERTEX_INCLUSION, VERTEX_EXCLUSION):
                ring.append((n, e))
                if len(ring) == int(it.param1):
                    target = (
                        shapes.inclusion if it.command == VERTEX_INCLUSION else shapes.exclusion
                    )
                    target.append(ring)
                    ring = []
            elif it.command == CIRCLE_INCLUSION:
                shapes.circles_in.append(((n, e), it.param1))
            elif it.command == CIRCLE_EXCLUSION:
                shapes.circles_out.append(((n, e), it.param1))
        return shapes

    def outside_by(self, p: tuple[float, float]) -> float:
        """How far `p` is on the wrong side of the fence (0: within it)."""
        worst = 0.0
        for ring in self.inclusion:
            if not _inside(p, ring):
                worst = max(worst, _distance_to_ring(p, ring))
        for ring in self.exclusion:
            if _inside(p, ring):
                worst = max(worst, _distance_to_ring(p, ring))
        for c, r in self.circles_in:
            worst = max(worst, math.dist(p, c) - r)
        for c, r in self.circles_out:
            worst = max(worst, r - math.dist(p, c))
        return worst


class TypedUpload:
    """An upload of a fence or rally list: request each seq, then the whole list is judged."""

    def __init__(self, mission_type: int, count: int) -> None:
        self.mission_type = mission_type
        self.count = count
        self.items: list[ms.Item] = []

    @property
    def expected(self) -> int:
        """The seq waited for."""
        return len(self.items)


@dataclass
class FenceState:
    """What the autopilot keeps of its fence: the lists, the parameters, the breach."""

    stored: dict[int, list[ms.Item]] = field(
        default_factory=lambda: {MISSION_TYPE_FENCE: [], MISSION_TYPE_RALLY: []}
    )
    params: dict[str, tuple[float, int]] = field(default_factory=lambda: dict(DEFAULT_PARAMS))
    shapes: Shapes = field(default_factory=Shapes)
    upload: TypedUpload | None = None
    breach_type: int = BREACH_NONE
    breach_count: int = 0
    breach_time_ms: int = 0
    breach_at: tuple[float, float, float] | None = None  # NED where the last breach began
    status_at: float = -math.inf


class FenceMixin:
    """Fence and rally storage, fence parameters and enforcement of `Copter`."""

    origin: GeoOrigin
    config: Any
    armed: bool
    mode: int
    t: float
    dyn: Any

    def send(self, msg: Any, link: Any = None) -> None:
        """Queue a message (implemented by Copter)."""
        raise NotImplementedError

    def text(self, severity: int, text: str, throttle_s: float = 0.0) -> None:
        """Queue a STATUSTEXT (implemented by Copter)."""
        raise NotImplementedError

    def set_mode(self, mode: int) -> bool:
        """Change mode (implemented by Copter)."""
        raise NotImplementedError

    def estimated_position(self) -> tuple[float, float, float]:
        """NED from home (implemented by Copter)."""
        raise NotImplementedError

    @property
    def fence(self) -> FenceState:
        """The fence's state, made on first use (empty lists, ArduPilot's default parameters)."""
        state = self.__dict__.get("_fence_state")
        if state is None:
            state = self.__dict__["_fence_state"] = FenceState()
        return state

    def autopilot_version(self) -> Any:
        """AUTOPILOT_VERSION: MAVLink 2, MISSION_INT, and fence/rally over the mission protocol
        when this release has them (habit `mission_fence`)."""
        caps = CAP_MISSION_INT | CAP_MAVLINK2
        if self.config.habits.mission_fence:
            caps |= CAP_MISSION_FENCE | CAP_MISSION_RALLY
        version = (
            (4 << 24) | (5 << 16) if self.config.habits.mission_fence else (3 << 24) | (7 << 16)
        )
        return mavlink.MAVLink_autopilot_version_message(
            caps, version, 0, 0, 0, [0] * 8, [0] * 8, [0] * 8, 0, 0, 0
        )

    def param(self, name: str) -> float:
        """A parameter's value."""
        return self.fence.params[name][0]

    # --- transfers of fence and rally lists -------------------------------------------------
    def _ack(self, link: Any, result: int, mission_type: int) -> None:
        self.send(mavlink.MAVLink_mission_ack_message(255, 0, result, mission_type), link)

    def _typed_count(self, msg: Any, link: Any) -> None:
        kind = msg.mission_type
        if kind not in self.fence.stored or not self.config.habits.mission_fence:
            self._ack(link, ms.UNSUPPORTED, kind)
            return
        limit = MAX_FENCE_ITEMS if kind == MISSION_TYPE_FENCE else MAX_RALLY_POINTS
        if msg.count > limit:
            self._ack(link, ms.NO_SPACE, kind)
            return
        up = self.fence.upload
        if up is None or up.mission_type != kind or up.count != msg.count:
            self.fence.upload = up = TypedUpload(kind, msg.count)
        if msg.count == 0:
            self._store(up, link)
            return
        self.send(mavlink.MAVLink_mission_request_int_message(255, 0, up.expected, kind), link)

    def _typed_item(self, msg: Any, link: Any) -> None:
        up = self.fence.upload
        if up is None or up.mission_type != msg.mission_type or msg.seq != up.expected:
            if up is not None and msg.seq > up.expected:
                self.send(
                    mavlink.MAVLink_mission_request_int_message(
                        255, 0, up.expected, up.mission_type
                    ),
                    link,
                )
            return
        if up.mission_type == MISSION_TYPE_RALLY and msg.command != RALLY_POINT:
            self.fence.upload = None
            self._ack(link, ms.UNSUPPORTED, up.mission_type)
            return
        if up.mission_type == MISSION_TYPE_FENCE and msg.command not in FENCE_COMMANDS:
            self.fence.upload = None
            self._ack(link, ms.UNSUPPORTED, up.mission_type)
            return
        rally = up.mission_type == MISSION_TYPE_RALLY
        up.items.append(
            ms.Item(
                msg.seq,
                msg.frame if rally else ms.FRAME_GLOBAL,
                msg.command,
                float(msg.param1) if not rally else 0.0,
                0.0,
                0.0,
                0.0,
                msg.x,
                msg.y,
                float(int(msg.z)) if rally else 0.0,  # rally: int16 metres; fence: no altitude
            )
        )
        if len(up.items) < up.count:
            self.send(
                mavlink.MAVLink_mission_request_int_message(255, 0, up.expected, up.mission_type),
                link,
            )
            return
        self._store(up, link)

    def _store(self, up: TypedUpload, link: Any) -> None:
        self.fence.upload = None
        if up.mission_type == MISSION_TYPE_FENCE and not validate_fence(up.items):
            self.text(CRITICAL, "Fence validation failed")
            self._ack(link, ms.ERROR, up.mission_type)
            return
        self.fence.stored[up.mission_type] = up.items
        if up.mission_type == MISSION_TYPE_FENCE:
            self.fence.shapes = Shapes.of(up.items, self.origin)
        self._ack(link, ms.ACCEPTED, up.mission_type)

    def _typed_request_list(self, msg: Any, link: Any) -> None:
        items = self.fence.stored.get(msg.mission_type, [])
        self.send(mavlink.MAVLink_mission_count_message(255, 0, len(items), msg.mission_type), link)

    def _typed_request(self, msg: Any, link: Any) -> None:
        items = self.fence.stored.get(msg.mission_type, [])
        if not 0 <= msg.seq < len(items):
            self._ack(link, ms.INVALID_SEQUENCE, msg.mission_type)
            return
        it = items[msg.seq]
        self.send(
            mavlink.MAVLink_mission_item_int_message(
                255, 0, it.seq, it.frame, it.command, 0, 1, it.param1, it.param2, it.param3,
                it.param4, it.x, it.y, it.z, msg.mission_type,
            ),
            link,
        )  # fmt: skip

    def _typed_clear(self, msg: Any, link: Any) -> None:
        if msg.mission_type in self.fence.stored:
            self.fence.stored[msg.mission_type] = []
            if msg.mission_type == MISSION_TYPE_FENCE:
                self.fence.shapes = Shapes()
        self._ack(link, ms.ACCEPTED, msg.mission_type)

    # --- parameters -------------------------------------------------------------------------
    def _param_value(self, name: str, link: Any = None) -> None:
        value, kind = self.fence.params[name]
        index = list(self.fence.params).index(name)
        self.send(
            mavlink.MAVLink_param_value_message(
                name.encode(), value, kind, len(self.fence.params), index
            ),
            link,
        )

    def set_param(self, name: str, value: float) -> bool:
        """Set a parameter this autopilot has (False: it has none of that name)."""
        if name not in self.fence.params or not math.isfinite(value):
            return False
        kind = self.fence.params[name][1]
        self.fence.params[name] = (float(int(value)) if kind == PARAM_INT8 else float(value), kind)
        return True

    def _on_param_set(self, msg: Any, link: Any) -> None:
        if not self.set_param(_param_name(msg.param_id), float(msg.param_value)):
            return  # ArduPilot answers nothing for a name it does not have
        self._param_value(_param_name(msg.param_id))  # to every link, as ArduPilot announces it

    def _on_param_request_read(self, msg: Any, link: Any) -> None:
        name = _param_name(msg.param_id)
        if name in self.fence.params:
            self._param_value(name, link)

    # --- enforcement ------------------------------------------------------------------------
    def fence_tick(self, flying: bool) -> None:
        """Check for a breach and act on a new one; FENCE_STATUS once a second while enabled."""
        if self.param("FENCE_ENABLE") < 1:
            self.fence.breach_type = BREACH_NONE
            return
        n, e, d = self.estimated_position()
        kinds = int(self.param("FENCE_TYPE"))
        outside = self.fence.shapes.outside_by((n, e)) if kinds & TYPE_POLYGON else 0.0
        above = -d - self.param("FENCE_ALT_MAX") if kinds & TYPE_ALT_MAX else -math.inf
        now = BREACH_BOUNDARY if outside > 0 else BREACH_MAXALT if above > 0 else BREACH_NONE
        if now != BREACH_NONE and self.fence.breach_type == BREACH_NONE and self.armed:
            self.fence.breach_count += 1
            self.fence.breach_time_ms = int(self.t * 1000)
            self.fence.breach_at = (n, e, d)
            if flying:
                self._breach_action(max(outside, above))
        self.fence.breach_type = now if self.armed else BREACH_NONE
        if self.t - self.fence.status_at >= 1.0:
            self.fence.status_at = self.t
            self.send(
                mavlink.MAVLink_fence_status_message(
                    int(self.fence.breach_type != BREACH_NONE), self.fence.breach_count, self.fence.breach_type,
                    self.fence.breach_time_ms, 0,
                )
            )  # fmt: skip

    def _breach_action(self, distance_m: float) -> None:
        self.text(CRITICAL, "Fence Breached")
        if self.param("FENCE_ACTION") == 0 or self.mode in (RTL, LAND):
            return
        if distance_m > GIVE_UP_DISTANCE_M or not self.set_mode(RTL):
            self.set_mode(LAND)


def _param_name(param_id: Any) -> str:
    raw = param_id.decode("ascii", "replace") if isinstance(param_id, bytes) else str(param_id)
    return raw.rstrip("\x00")
