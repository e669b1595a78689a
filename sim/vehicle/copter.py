"""The simulated flight controller: ArduPilot Copter modes, arming, commands and mission flight.

`Copter` has no sockets and no clock: `handle(msg, link, wall)` takes one decoded MAVLink
message, `tick(dt, wall)` advances simulated time, and everything to send lands in `outbox`
as (link, message) pairs — link None means every connected peer. Positions the autopilot
believes (missions, guided targets, telemetry) are in the estimated frame: truth plus the
GNSS error; the dynamics fly the truth, so a vehicle lands where its GNSS says the pad is.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass, field
from typing import Any, Literal, Protocol

from pymavlink.dialects.v20 import ardupilotmega as mavlink

from protocol.rtcm import MavlinkReassembler, Reframer, frame_ok
from sim.vehicle import mission as ms
from sim.vehicle.boot import BootMixin
from sim.vehicle.commands import NO_ANSWER, run_command
from sim.vehicle.constants import (
    ACCEPTED,
    AUTO,
    BRAKE,
    CRITICAL,
    FAILED,
    GUIDED,
    INFO,
    LOITER,
    MODE_NAMES,
    NOT_ARMABLE,
    RTL,
    STABILIZE,
    SUPPORTED_MODES,
    WARNING,
)  # fmt: skip
from sim.vehicle.dynamics import Dynamics, DynamicsParams
from sim.vehicle.failsafe import check_battery
from sim.vehicle.faults import Faults
from sim.vehicle.geo import GeoOrigin
from sim.vehicle.gnss import FIX_3D, GnssModel, GnssParams, GnssReading
from sim.vehicle.guidance import Guidance
from sim.vehicle.habits import Habits
from sim.vehicle.mission_link import MissionProtocolMixin
from sim.vehicle.plnd_flight import landing_target, plnd_update, precision_landing_habit
from sim.vehicle.precland import PrecisionLanding
from sim.wind import Airflow, AirflowParams


class Base(Protocol):
    """What the vehicle needs from the landing base it lives on (the world's simulated base)."""

    def can_vehicle_leave(self) -> bool:
        """True when panels are open and the lift is up."""
        ...

    def set_pad_load(self, mass_g: float, contacts_seated: bool) -> None:
        """The vehicle's mass on the scale and whether the charging contacts are seated."""
        ...

    @property
    def pad_geodetic(self) -> tuple[float, float, float]:
        """The pad centre: latitude, longitude (degrees), altitude (m MSL)."""
        ...


log = logging.getLogger(__name__)


@dataclass(frozen=True)
class CopterConfig:
    """Tunables, named after the ArduPilot parameters they stand for."""

    seed: int | None = None
    wp_speed: float = 10.0  # WPNAV_SPEED, m/s
    wp_radius: float = 1.0  # WPNAV_RADIUS, m
    rtl_alt: float = 15.0  # RTL_ALT, m
    rtl_loiter_s: float = 2.0  # RTL_LOIT_TIME
    land_speed: float = 0.5  # LAND_SPEED
    land_speed_high: float = 1.5  # LAND_SPEED_HIGH
    land_alt_low: float = 10.0  # LAND_ALT_LOW
    arm_min_battery_pct: float = 30.0  # BATT_ARM_MAH as a percentage
    failsafe_battery_pct: float = 15.0  # BATT_LOW as a percentage
    # BATT_FS_LOW_ACT: "rtl" (2), "land" (1), "none" (0, ArduPilot's default: a warning and the
    # HEARTBEAT's system_status CRITICAL only); FS_OPTIONS bit 3, CONTINUE_IF_LANDING
    failsafe_battery_action: Literal["none", "land", "rtl"] = "rtl"
    failsafe_continue_landing: bool = True
    guided_timeout_s: float = 3.0  # GUID_TIMEOUT for velocity targets
    mission_resend_s: float = 1.0  # re-request a missing mission item (wall seconds)
    mission_timeout_s: float = 8.0  # cancel an upload after this much silence (wall seconds)
    pad_radius_m: float = 0.6  # landing inside this radius puts the mass on the scale
    contacts_tolerance_m: float = 0.05  # charging contacts seat inside this radius
    dynamics: DynamicsParams = field(default_factory=DynamicsParams)
    airflow: AirflowParams = field(default_factory=AirflowParams)  # shear and turbulence
    gnss: GnssParams = field(default_factory=GnssParams)
    habits: Habits = field(default_factory=Habits)  # which ArduPilot release it behaves as
    powered_s: float = 0.0  # its uptime at the start: time_boot_ms wraps at 49.7 days (boot.py)


def _ack(request: Any, command: int, result: int) -> Any:
    """COMMAND_ACK addressed to the sender of `request`, as ArduPilot fills it."""
    return mavlink.MAVLink_command_ack_message(
        command, result, 0, 0, request.get_srcSystem(), request.get_srcComponent()
    )


class Copter(MissionProtocolMixin, BootMixin):
    """One ArduPilot-Copter-like vehicle on its base."""

    def __init__(self, base: Base, config: CopterConfig | None = None) -> None:
        self.config = cfg = config or CopterConfig()
        self.base = base
        self.origin = GeoOrigin(*base.pad_geodetic)
        self.dyn = Dynamics(cfg.dynamics)
        self.airflow = Airflow(cfg.airflow, seed=cfg.seed)  # the air at the vehicle (sim/wind.py)
        self.gnss = GnssModel(cfg.gnss, seed=cfg.seed)
        self.precland = PrecisionLanding()  # the simulator's own, when no PLND habit
        self.plnd = precision_landing_habit(self)  # ArduPilot's PLND, when the habit says so
        self.guidance = Guidance(self)
        self.faults = Faults()
        self.t = 0.0  # simulated seconds since the simulation started
        self.wall = 0.0
        self.init_boot()
        self.mode = STABILIZE
        self.armed = False
        self.failsafe = False
        self.items: list[ms.Item] = [self.home_item()]
        self.mission_id = 0  # the plan's opaque id (mission_report.py)
        self.mission_current = 0
        self.upload: ms.Upload | None = None
        self.upload_link: Any = None
        self.outbox: list[tuple[Any, Any]] = []
        self.reading: GnssReading = self.gnss.reading(0.0)
        self._rtcm_inputs: dict[Any, tuple[MavlinkReassembler, Reframer]] = {}
        self._text_times: dict[str, float] = {}
        self._was_landed = True
        self._blocked_told = False
        base.set_pad_load(cfg.dynamics.mass_g, True)
        self._share_battery(self.dyn.state.battery_pct / 100.0)

    # --- frames ----------------------------------------------------------------------------
    def home_item(self) -> ms.Item:
        """Item 0: home, at the pad."""
        lat, lon, alt = self.origin.lat, self.origin.lon, self.origin.alt
        return ms.Item(
            0, ms.FRAME_GLOBAL, ms.NAV_WAYPOINT, x=round(lat * 1e7), y=round(lon * 1e7), z=alt
        )

    def estimated_position(self) -> tuple[float, float, float]:
        """Where the autopilot believes it is (NED from home): truth plus the GNSS error."""
        n, e, d = self.dyn.state.position
        err = self.reading.error_ned
        return n + err[0], e + err[1], d

    def item_ned(self, item: ms.Item) -> tuple[float, float, float]:
        """A mission item's position in local NED; lat/lon 0 means here."""
        est = self.estimated_position()
        if item.x == 0 and item.y == 0:
            n, e = est[0], est[1]
        else:
            n, e, _ = self.origin.to_ned(item.lat, item.lon, self.origin.alt)
        rel = item.z if item.frame in ms.RELATIVE_FRAMES else item.z - self.origin.alt
        return n, e, -rel

    def pad_distance(self) -> float:
        """True horizontal distance from the pad centre, metres."""
        n, e, _ = self.dyn.state.position
        return math.hypot(n, e)

    @property
    def flying(self) -> bool:
        """True when armed and off the ground."""
        return self.armed and not self.dyn.state.landed

    # --- output ----------------------------------------------------------------------------
    def send(self, msg: Any, link: Any = None) -> None:
        """Queue a message for one link (or every link when None)."""
        self.outbox.append((link, msg))

    def text(self, severity: int, text: str, throttle_s: float = 0.0) -> None:
        """Queue a STATUSTEXT, at most once per `throttle_s` wall seconds for the same text."""
        last = self._text_times.get(text)
        if throttle_s and last is not None and self.wall - last < throttle_s:
            return
        self._text_times[text] = self.wall
        self.send(mavlink.MAVLink_statustext_message(severity, text[:50].encode()))

    # --- arming and modes -------------------------------------------------------------------
    def prearm_failure(self, arming: bool = True) -> str | None:
        """Why the vehicle may not arm now, or None; `arming=False` leaves out base and mode (health)."""
        if self.faults.prearm_failure:
            return self.faults.prearm_failure
        booting = self.booting_text()
        if booting:
            return booting
        if self.reading.fix_type < FIX_3D:
            return "GPS 1: Bad fix"
        if self.dyn.state.battery_pct < self.config.arm_min_battery_pct:
            return "Battery 1 below minimum arming capacity"
        if arming and self.on_pad() and not self.base.can_vehicle_leave():
            return "Base closed"
        if arming and self.mode in NOT_ARMABLE:
            return "Mode not armable"
        return None

    def arm(self, force: bool = False) -> int:
        """Arm the motors after the pre-arm checks; a MAV_RESULT."""
        if self.armed:
            return ACCEPTED
        reason = None if force else self.prearm_failure()
        if reason:
            self.text(CRITICAL, f"PreArm: {reason}")
            return FAILED
        self.armed = True
        self.dyn.motors_on = True
        self.guidance.on_arming()
        self.text(INFO, "Arming motors")
        return ACCEPTED

    def disarm(self, force: bool = False) -> int:
        """Disarm; refused in flight unless forced; a MAV_RESULT."""
        if not self.armed:
            return ACCEPTED
        if self.flying and not force:
            return FAILED
        self.armed = False
        self.dyn.motors_on = False
        self.text(INFO, "Disarming motors")
        return ACCEPTED

    def set_mode(self, mode: int) -> bool:
        """Change flight mode as ArduPilot would; False when refused."""
        if mode not in SUPPORTED_MODES:
            return False
        needs_position = mode in (AUTO, GUIDED, LOITER, RTL, BRAKE)
        if needs_position and self.reading.fix_type < FIX_3D:
            self.text(WARNING, f"Flight mode change failed: {MODE_NAMES[mode]} needs position")
            return False
        if (
            mode == AUTO
            and self.armed
            and self.dyn.state.landed
            and not ms.starts_with_takeoff(self.items)
        ):
            self.text(CRITICAL, "Auto: Missing Takeoff Cmd")
            return False
        self.mode = mode
        self.guidance.enter_mode(mode)
        return True

    def on_pad(self) -> bool:
        """True when landed within the pad radius."""
        return self.dyn.state.landed and self.pad_distance() <= self.config.pad_radius_m

    # --- time ------------------------------------------------------------------------------
    def tick(self, dt: float, wall: float, wind_ne: tuple[float, float] = (0.0, 0.0)) -> None:
        """Advance `dt` simulated seconds (wall time `wall` for protocol timers) in the wind
        `wind_ne` 20 ft above the ground (Weather.flow_ne; `Airflow` adds shear, turbulence)."""
        self.wall = wall
        self.t += dt
        self._boot_tick(wall)
        self.reading = self.gnss.step(dt, wall)
        if self.upload is not None and not self.faults.drop_mission:
            action = self.upload.update(wall)
            if action:
                self._upload_action(action)
        plnd_update(self, dt)
        blocked = self.on_pad() and self.armed and not self.base.can_vehicle_leave()
        self.guidance.update(dt, blocked)
        if blocked and not self._blocked_told:
            self.text(WARNING, "Base closed: cannot take off")
        self._blocked_told = blocked
        st = self.dyn.state
        air = self.airflow.step(dt, wind_ne, st.altitude, (st.velocity[0], st.velocity[1]))
        self.dyn.step(dt, (air[0], air[1]))
        self.fence_tick(self.flying)
        self._check_landing()
        check_battery(self)

    def _check_landing(self) -> None:
        landed = self.dyn.state.landed
        if landed != self._was_landed:
            self._was_landed = landed
            log.info(
                "vehicle %s %.3f m from the pad centre",
                "landed" if landed else "lifted off",
                self.pad_distance(),
            )
            if not landed:
                self.base.set_pad_load(0.0, False)
                self._share_battery(None)
            elif self.pad_distance() <= self.config.pad_radius_m:
                seated = self.pad_distance() <= self.config.contacts_tolerance_m
                self.base.set_pad_load(self.config.dynamics.mass_g, seated)
                self._share_battery(self.dyn.state.battery_pct / 100.0 if seated else None)
        elif landed and not self.armed:
            self._charge_from_base()

    def _share_battery(self, soc: float | None) -> None:
        """Optional base extension: tell a base with a charger what battery sits on its contacts."""
        share = getattr(self.base, "set_uav_battery", None)
        if callable(share):
            share(soc)

    def _charge_from_base(self) -> None:
        """Optional base extension: follow the charger's state of charge while seated."""
        soc = getattr(getattr(self.base, "charger", None), "uav_soc", None)
        if soc is None and getattr(self.base, "contacts_seated", False):
            # seated but the charger has not heard of this battery (placed at start, or a touchdown
            # bounce re-seated it): the battery is there, so tell the charger
            self._share_battery(self.dyn.state.battery_pct / 100.0)
            return
        if isinstance(soc, float | int) and abs(soc * 100.0 - self.dyn.state.battery_pct) > 0.01:
            self.dyn.set_battery(soc * 100.0)

    # --- input -----------------------------------------------------------------------------
    def handle(self, msg: Any, link: Any, wall: float) -> None:
        """Act on one decoded MAVLink message received on `link`."""
        self.wall = wall
        if self.rebooting(wall):
            return
        kind = msg.get_type()
        target = getattr(msg, "target_system", 0)
        if target not in (0, 1):
            return
        if kind.startswith("MISSION_") and self.faults.drop_mission:
            return
        handler = getattr(self, f"_on_{kind.lower()}", None)
        if handler is not None:
            handler(msg, link)

    def _on_command_long(self, msg: Any, link: Any) -> None:
        p = (msg.param1, msg.param2, msg.param3, msg.param4, msg.param5, msg.param6, msg.param7)
        self._answer(msg, msg.command, run_command(self, msg.command, p, link), link)

    def _on_command_int(self, msg: Any, link: Any) -> None:
        p = (msg.param1, msg.param2, msg.param3, msg.param4, msg.x / 1e7, msg.y / 1e7, msg.z)
        self._answer(msg, msg.command, run_command(self, msg.command, p, link), link)

    def _on_set_mode(self, msg: Any, link: Any) -> None:
        self._answer(msg, 11, ACCEPTED if self.set_mode(msg.custom_mode) else FAILED, link)

    def _answer(self, request: Any, command: int, result: int, link: Any) -> None:
        """The COMMAND_ACK for `request`, unless the command gives none or the fault loses it."""
        if result == NO_ANSWER:
            return
        if self.faults.drop_acks > 0:
            self.faults.drop_acks -= 1
            return
        self.send(_ack(request, command, result), link)

    def _on_set_position_target_local_ned(self, msg: Any, link: Any) -> None:
        if self.mode == GUIDED and self.armed:
            self.guidance.guided_target(msg)

    def _on_set_position_target_global_int(self, msg: Any, link: Any) -> None:
        if self.mode == GUIDED and self.armed:
            self.guidance.guided_global_target(msg)

    def _on_landing_target(self, msg: Any, link: Any) -> None:
        landing_target(self, msg)

    def _on_gps_rtcm_data(self, msg: Any, link: Any) -> None:
        # as a GNSS receiver does: the injected bytes are one stream, re-framed and CRC-checked
        # (a frame longer than one GPS_RTCM_DATA message arrives in consecutive messages)
        reassembler, reframer = self._rtcm_inputs.setdefault(
            link, (MavlinkReassembler(), Reframer())
        )
        message = reassembler.push(msg.flags, bytes(msg.data[: msg.len]))
        if message is None:
            return
        bad_before = reframer.bad_frames
        for frame in reframer.feed(message):
            self.gnss.correction(self.wall, frame_ok(frame))
        for _ in range(reframer.bad_frames - bad_before):
            self.gnss.correction(self.wall, False)

    def _on_request_data_stream(self, msg: Any, link: Any) -> None:
        streams = self.streams_for(link)
        if streams is not None:
            streams.request_data_stream(msg.req_stream_id, msg.req_message_rate, msg.start_stop)

    @staticmethod
    def streams_for(link: Any) -> Any:
        """The stream scheduler of a link (each link has its own rates), or None."""
        return getattr(link, "streams", None)
