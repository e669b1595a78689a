"""What each flight mode flies: hold, guided targets, takeoff, mission items, RTL, landing.

Goals are kept in the estimated frame (what the autopilot believes) and turned into true
targets for the dynamics every tick by subtracting the current GNSS error.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from pymavlink.dialects.v20 import ardupilotmega as mavlink

from sim.vehicle import mission as ms
from sim.vehicle.constants import (
    ACCEPTED,
    AUTO,
    FAILED,
    GUIDED,
    IN_AIR,
    INFO,
    LAND,
    LANDING,
    MISSION_ACTIVE,
    MISSION_COMPLETE,
    MISSION_NONE,
    MISSION_NOT_STARTED,
    MISSION_PAUSED,
    ON_GROUND,
    RTL,
    TAKEOFF,
)  # fmt: skip
from sim.vehicle.disarm import auto_disarm
from sim.vehicle.plnd_flight import land_with_plnd

if TYPE_CHECKING:
    from sim.vehicle.copter import Copter

LAND_DETECTOR_S = 1.0  # ArduPilot's LAND_DETECTOR_TRIGGER_SEC: on the ground this long, landed
POS_IGNORE, VEL_IGNORE, YAW_IGNORE = 0b000000111, 0b000111000, 0b10000000000
FRAME_LOCAL_NED, FRAME_LOCAL_OFFSET_NED, FRAME_BODY_NED, FRAME_BODY_OFFSET_NED = 1, 7, 8, 9


@dataclass(frozen=True)
class Goal:
    """One thing to fly: hold/goto a point, land at a point, or follow a velocity."""

    kind: str  # "goto" | "land" | "vel"
    n: float = 0.0
    e: float = 0.0
    d: float = 0.0
    speed: float | None = None
    expires: float = math.inf  # for "vel"


class Guidance:
    """The mode logic of one `Copter`; it owns the goal and the mission progress."""

    def __init__(self, copter: Copter) -> None:
        self.c = copter
        self.goal = Goal("goto")
        self.speed = copter.config.wp_speed
        self.mission_state = MISSION_NONE
        self.rtl_phase: str | None = None
        self._rtl_alt = 0.0
        self._arrived_at: float | None = None
        self._taking_off = False
        self._landed_s = LAND_DETECTOR_S  # on the ground this long (it starts there)
        self.idle_since: float | None = None  # wall time it began idling armed on the ground
        self._target_seen = False
        self._jumps: dict[int, int] = {}
        self.yaw_target: float | None = None

    # --- entry points --------------------------------------------------------------------
    def hold(self) -> None:
        """Hold the current estimated position."""
        n, e, d = self.c.estimated_position()
        self.goal = Goal("goto", n, e, min(d, 0.0))
        self._taking_off = False

    def on_arming(self) -> None:
        """Armed: hold here; the auto-disarm timer starts (disarm.py)."""
        self.idle_since = None
        self.hold()

    def enter_mode(self, mode: int) -> None:
        """A mode change happened: set up what the new mode flies."""
        c = self.c
        self.rtl_phase = None
        if c.plnd is not None:  # AC_PrecLand_StateMachine::init, on every mode change
            c.plnd.machine_reset()
            c.plnd.retries = 0
        if self.mission_state == MISSION_ACTIVE and mode != AUTO:
            self.mission_state = MISSION_PAUSED
        if not c.armed:
            self.hold()
            return
        if mode == AUTO:
            self.start_or_resume()
        elif mode == RTL:
            self.rtl_start()
        elif mode == LAND:
            self.land_here()
        else:
            self.hold()

    def mission_cleared(self) -> None:
        """The mission was cleared: stop flying it."""
        self.mission_state = MISSION_NONE
        if self.c.mode == AUTO and self.c.armed:
            self.hold()

    @property
    def land_complete(self) -> bool:
        """ArduPilot's `ap.land_complete`: its land detector has seen the vehicle on the ground
        for LAND_DETECTOR_S. Then LAND disarms, GUIDED idles and EXTENDED_SYS_STATE says ON_GROUND;
        in the second before, GUIDED still flies (a climb sent then lifts the vehicle again)."""
        return self._landed_s >= LAND_DETECTOR_S

    def takeoff(self, alt: float) -> int:
        """GUIDED takeoff to `alt` metres above home; a MAV_RESULT."""
        c = self.c
        if c.mode != GUIDED or not c.armed or not c.dyn.state.landed or alt <= 0:
            return FAILED
        n, e, _ = c.estimated_position()
        self.goal = Goal("goto", n, e, -alt)
        self._taking_off = True
        return ACCEPTED

    def start_or_resume(self) -> None:
        """AUTO: resume the current item, or start from item 1 when complete or not started."""
        c = self.c
        if len(c.items) <= 1:
            self.hold()
            return
        if self.mission_state in (MISSION_PAUSED, MISSION_ACTIVE) and c.mission_current >= 1:
            self.start_item(c.mission_current)
        else:
            self._jumps.clear()
            self.start_item(1)

    def guided_target(self, msg: Any) -> None:
        """Apply a SET_POSITION_TARGET_LOCAL_NED in GUIDED."""
        c = self.c
        frame, mask = msg.coordinate_frame, msg.type_mask
        if frame not in (
            FRAME_LOCAL_NED,
            FRAME_LOCAL_OFFSET_NED,
            FRAME_BODY_NED,
            FRAME_BODY_OFFSET_NED,
        ):
            return
        yaw = c.dyn.state.yaw if frame in (FRAME_BODY_NED, FRAME_BODY_OFFSET_NED) else 0.0

        def rot(x: float, y: float) -> tuple[float, float]:
            return x * math.cos(yaw) - y * math.sin(yaw), x * math.sin(yaw) + y * math.cos(yaw)

        self._taking_off = False
        if not mask & YAW_IGNORE:
            self.yaw_target = msg.yaw
        if not mask & POS_IGNORE:
            n, e = rot(msg.x, msg.y)
            d = msg.z
            if frame != FRAME_LOCAL_NED:
                est = c.estimated_position()
                n, e, d = n + est[0], e + est[1], d + est[2]
            self.goal = Goal("goto", n, e, min(d, 0.0))
        elif not mask & VEL_IGNORE:
            vn, ve = rot(msg.vx, msg.vy)
            self.goal = Goal("vel", vn, ve, msg.vz, expires=c.t + c.config.guided_timeout_s)

    def guided_global_target(self, msg: Any) -> None:
        """Apply a SET_POSITION_TARGET_GLOBAL_INT in GUIDED (positions in degrees * 1e7)."""
        c = self.c
        frame, mask = msg.coordinate_frame, msg.type_mask
        if frame not in (ms.FRAME_GLOBAL_INT, ms.FRAME_GLOBAL_RELATIVE_ALT_INT, 0, 3):
            return
        self._taking_off = False
        if not mask & YAW_IGNORE:
            self.yaw_target = msg.yaw
        if not mask & POS_IGNORE:
            n, e, _ = c.origin.to_ned(msg.lat_int / 1e7, msg.lon_int / 1e7, c.origin.alt)
            rel = msg.alt if frame in ms.RELATIVE_FRAMES else msg.alt - c.origin.alt
            self.goal = Goal("goto", n, e, min(-rel, 0.0))
        elif not mask & VEL_IGNORE:
            self.goal = Goal("vel", msg.vx, msg.vy, msg.vz, expires=c.t + c.config.guided_timeout_s)

    def condition_yaw(self, angle_deg: float, direction: float, relative: bool) -> None:
        """MAV_CMD_CONDITION_YAW: turn to a heading, or by an angle (direction -1 ccw, 1 cw)."""
        if relative:
            sign = -1.0 if direction < 0 else 1.0
            self.yaw_target = self.c.dyn.state.yaw + sign * math.radians(angle_deg)
        else:
            self.yaw_target = math.radians(angle_deg)

    def start_item(self, seq: int, chain: int = 0) -> None:
        """AUTO: begin mission item `seq` (`chain` counts items stepped over without flying)."""
        c = self.c
        if seq >= len(c.items) or chain > 2 * len(c.items):  # the end, or a loop of DO_JUMPs
            self._complete()
            return
        c.mission_current = seq
        self.mission_state = MISSION_ACTIVE
        self._arrived_at = None
        self.rtl_phase = None
        item = c.items[seq]
        n, e, d = c.item_ned(item)
        c.text(INFO, f"Mission: {seq} {ms.CMD_NAMES.get(item.command, item.command)}")
        if item.command == ms.DO_CHANGE_SPEED:
            self.speed = item.param2
            self.start_item(seq + 1, chain + 1)
        elif item.command == ms.DO_JUMP:
            self._jump(seq, item, chain)
        elif item.command not in ms.NAV_COMMANDS:
            self.start_item(seq + 1, chain + 1)  # camera, gimbal, yaw, delay...: nothing to fly
        elif item.command == ms.NAV_TAKEOFF:
            est = c.estimated_position()
            self.goal = Goal("goto", est[0], est[1], min(d, est[2]))
            self._taking_off = True
        elif item.command == ms.NAV_DELAY:
            self.hold()
            self._arrived_at = c.t
        elif item.command == ms.NAV_LAND:
            self.goal = Goal("land", n, e)
        elif item.command == ms.NAV_RETURN_TO_LAUNCH:
            self.rtl_start()
        else:  # waypoints and loiters
            self.goal = Goal("goto", n, e, d, self.speed)

    def _jump(self, seq: int, item: ms.Item, chain: int) -> None:
        """DO_JUMP: back to param1, param2 times (-1: for ever), then on."""
        left = self._jumps.setdefault(seq, int(item.param2))
        if left == 0 or not 1 <= int(item.param1) < len(self.c.items):
            self.start_item(seq + 1, chain + 1)
            return
        if left > 0:
            self._jumps[seq] = left - 1
        self.start_item(int(item.param1), chain + 1)

    def land_here(self) -> None:
        """LAND: descend at the current estimated position (or onto a landing target)."""
        n, e, _ = self.c.estimated_position()
        self.goal = Goal("land", n, e)

    def rtl_start(self) -> None:
        """RTL: climb to RTL_ALT, return home, loiter, land."""
        c = self.c
        if c.dyn.state.landed:
            self.rtl_phase = "land"
            self.goal = Goal("land", 0.0, 0.0)
            return
        n, e, _ = c.estimated_position()
        self._rtl_alt = max(c.config.rtl_alt, c.dyn.state.altitude)
        self.rtl_phase = "climb"
        self.goal = Goal("goto", n, e, -self._rtl_alt)

    # --- every tick ------------------------------------------------------------------------
    def update(self, dt: float, blocked: bool) -> None:
        """Advance the mode logic and hand the dynamics a true target."""
        c = self.c
        self._landed_s = self._landed_s + dt if c.dyn.state.landed else 0.0
        if auto_disarm(self) or not c.armed:
            return
        if self.goal.kind == "land" and self.land_complete:
            self._touched_down()
            return
        if c.mode == AUTO and self.mission_state == MISSION_ACTIVE:
            self._auto_update()
        if self.rtl_phase and self.rtl_phase != "land":
            self._rtl_update()
        if self._taking_off and c.dyn.state.altitude >= -self.goal.d - 0.3:
            self._taking_off = False
        if self.goal.kind == "vel" and c.t > self.goal.expires:
            self.hold()
        self._apply(blocked)

    def _apply(self, blocked: bool) -> None:
        c, g = self.c, self.goal
        err = c.reading.error_ned
        dyn = c.dyn
        # GUIDED landed: ArduPilot's controllers idle (is_disarmed_or_landed), no target lifts
        # the vehicle, only a takeoff command does (a climb sent there stays on the ground)
        if blocked or (c.mode == GUIDED and self.land_complete and not self._taking_off):
            n, e, _ = dyn.state.position
            dyn.set_position_target((n, e, 0.0))
            return
        if g.kind == "vel":
            dyn.set_velocity_target((g.n, g.e, g.d), yaw=self.yaw_target)
            return
        if g.kind == "goto":
            dyn.set_position_target(
                (g.n - err[0], g.e - err[1], g.d), yaw=self.yaw_target, speed_h=g.speed
            )
            return
        if c.plnd is not None:
            land_with_plnd(self)
            return
        tn, te = g.n, g.e
        target = c.precland.target_ne(c.t)
        if target is not None:
            tn, te = target
            # keep landing at the last estimate if the target is lost later
            self.goal = Goal("land", tn, te)
            if not self._target_seen:
                c.text(INFO, "PrecLand: Target Found")
        elif self._target_seen:
            c.text(INFO, "PrecLand: Target Lost")
        self._target_seen = target is not None
        alt = dyn.state.altitude
        cfg = c.config
        descend = cfg.land_speed if alt < cfg.land_alt_low else cfg.land_speed_high
        # ArduPilot holds the descent while far off the target horizontally
        offset = math.hypot(
            tn - err[0] - dyn.state.position[0], te - err[1] - dyn.state.position[1]
        )
        if target is not None and offset > max(1.0, 0.3 * alt):
            descend = 0.05
        dyn.set_position_target(
            (tn - err[0], te - err[1], 1.0), yaw=self.yaw_target, speed_down=descend
        )

    def _arrived(self, radius: float) -> bool:
        g = self.goal
        n, e, _ = self.c.estimated_position()
        alt_err = abs(self.c.dyn.state.position[2] - g.d)
        return math.hypot(g.n - n, g.e - e) <= radius and alt_err <= 0.5

    def _auto_update(self) -> None:
        c = self.c
        item = c.items[c.mission_current]
        if item.command == ms.NAV_TAKEOFF:
            if c.dyn.state.altitude >= -self.goal.d - 0.3:
                self._reached(c.mission_current)
            return
        hold_s = ms.HOLD_S.get(item.command)
        if hold_s is None:
            return  # land, RTL: done on touchdown; LOITER_UNLIM: never
        if self._arrived_at is None and self._arrived(c.config.wp_radius):
            self._arrived_at = c.t
        if self._arrived_at is not None and c.t - self._arrived_at >= hold_s(item):
            self._reached(c.mission_current)

    def _rtl_update(self) -> None:
        c = self.c
        if self.rtl_phase == "climb" and c.dyn.state.altitude >= self._rtl_alt - 0.5:
            self.rtl_phase = "return"
            # RTL flies RTL_SPEED, 0 meaning WPNAV_SPEED (ModeRTL::init), not a mission's speed
            self.goal = Goal("goto", 0.0, 0.0, -self._rtl_alt, c.config.wp_speed)
        elif self.rtl_phase == "return" and self._arrived(0.5):
            self.rtl_phase = "loiter"
            self._arrived_at = c.t
        elif (
            self.rtl_phase == "loiter" and c.t - (self._arrived_at or c.t) >= c.config.rtl_loiter_s
        ):
            self.rtl_phase = "land"
            self.goal = Goal("land", 0.0, 0.0)

    def _reached(self, seq: int) -> None:
        c = self.c
        c.send(mavlink.MAVLink_mission_item_reached_message(seq))
        c.text(INFO, f"Reached command #{seq}")
        self.start_item(seq + 1)

    def _complete(self) -> None:
        self.mission_state = MISSION_COMPLETE
        self.hold()

    def _touched_down(self) -> None:
        c = self.c
        if c.mode == AUTO and self.mission_state == MISSION_ACTIVE:
            seq = c.mission_current
            c.send(mavlink.MAVLink_mission_item_reached_message(seq))
            c.text(INFO, f"Reached command #{seq}")
            self.mission_state = MISSION_COMPLETE
        self.rtl_phase = None
        self.goal = Goal("goto", *c.estimated_position()[:2], 0.0)
        c.text(INFO, "Land complete")
        c.disarm()

    # --- reporting -------------------------------------------------------------------------
    def landed_state(self) -> int:
        """MAV_LANDED_STATE for EXTENDED_SYS_STATE."""
        c = self.c
        if self.land_complete and not (self._taking_off and c.armed):
            return ON_GROUND
        if self._taking_off:
            return TAKEOFF
        if self.goal.kind == "land":
            return LANDING
        return IN_AIR

    def reported_mission_state(self) -> int:
        """MISSION_STATE for MISSION_CURRENT, as GCS_MAVLINK::mission_state: a mission stopped by
        leaving AUTO (kept here as PAUSED, to resume at its item) reads NOT_STARTED."""
        if len(self.c.items) <= 1:
            return MISSION_NONE
        if self.mission_state in (MISSION_NONE, MISSION_PAUSED):
            return MISSION_NOT_STARTED
        return self.mission_state
