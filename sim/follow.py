"""The world follows an external autopilot instead of simulating one (`aerobase sim world --follow URL`).

A SITL or a real vehicle is flown by its own autopilot; the world watches it over a second,
read-only MAVLink connection (`sim.mavlink_link`) and makes the rest of the simulation agree:

- the base stands at the vehicle's home: the first ``HOME_POSITION`` (`Follower.wait_home`) is
  the pad (and so the GNSS base receiver's antenna). ArduPilot moves home to where it arms; the
  pad stays where it was built;
- the downward camera and the IR beacon see the pad from the vehicle's pose
  (`FollowerPart.pose`): north/east of the pad from ``SIMSTATE`` lat/lng when the autopilot is a
  SITL (its simulator's truth, in the EXTRA1 group: a camera sees where the vehicle is, not where
  its GNSS says it is), else from ``GLOBAL_POSITION_INT`` lat/lon (the autopilot's estimate; 1e-7°,
  about 1 cm), height from its ``relative_alt`` (above home), attitude from ``ATTITUDE``; the
  position is carried forward by the reported velocity over the age of the sample (at most
  `MAX_EXTRAPOLATION_S`) so a 25 Hz stream renders 30 fps smoothly;
- the base's scale carries the vehicle's mass while it is landed within `pad_radius_m` of the
  pad centre, and the charging contacts seat inside `contacts_tolerance_m` (judged at touchdown,
  held while it stays landed; before its first flight it stands on the pad, at home); landed is
  ``EXTENDED_SYS_STATE.landed_state == ON_GROUND`` when the autopilot sends it (ArduPilot 4.x,
  PX4), else ``relative_alt`` below `LANDED_ALT_M` with a vertical speed under `LANDED_VZ_MPS`.

The watch never commands the vehicle: it sends its own HEARTBEAT (system 253, an onboard
controller, so no GCS failsafe counts on it) and asks for the streams it needs — ``REQUEST_DATA_STREAM``
(every ArduPilot release) and ``SET_MESSAGE_INTERVAL`` (4.x, PX4) — again after every
(re)connection and whenever the pose has been silent for `SILENT_S`.
"""

from __future__ import annotations

import asyncio
import logging
import math
import time
from dataclasses import dataclass
from typing import Any

from pymavlink.dialects.v20 import ardupilotmega as mavlink

from asynckit.tasks import cancel_and_wait
from sim.camera.render import Pose
from sim.mavlink_link import MavlinkLink
from sim.vehicle.geo import GeoOrigin

log = logging.getLogger(__name__)

ATTITUDE, GLOBAL_POSITION_INT, SYS_STATUS, SIMSTATE = 30, 33, 1, 164
HOME_POSITION, EXTENDED_SYS_STATE = 242, 245
POSE_HZ = 25.0
# REQUEST_DATA_STREAM groups (ArduPilot): EXTENDED_STATUS, POSITION, EXTRA1 (attitude)
DATA_STREAMS = ((2, 2), (6, int(POSE_HZ)), (10, int(POSE_HZ)))
INTERVALS_HZ = {
    GLOBAL_POSITION_INT: POSE_HZ, ATTITUDE: POSE_HZ, SIMSTATE: POSE_HZ, EXTENDED_SYS_STATE: 5.0,
}  # fmt: skip
SILENT_S = 2.0  # wall seconds without a pose before asking for the streams again
HOME_ASK_S = 1.0  # wall seconds between requests for HOME_POSITION until it comes
MAX_EXTRAPOLATION_S = 0.3
TRUTH_FRESH_S = 1.0  # wall seconds a SIMSTATE position stands for the vehicle's
LANDED_ALT_M = 0.3
LANDED_VZ_MPS = 0.3
EXT_STATE_FRESH_S = 3.0
ON_GROUND = 1  # MAV_LANDED_STATE_ON_GROUND
CMD_GET_HOME_POSITION, CMD_SET_MESSAGE_INTERVAL, CMD_REQUEST_MESSAGE = 410, 511, 512


@dataclass(frozen=True)
class Sample:
    """One GLOBAL_POSITION_INT as received: degrees, metres above home, NED m/s, wall time."""

    lat: float
    lon: float
    rel_alt: float
    vn: float
    ve: float
    vd: float
    wall: float


class Follower:
    """What the external autopilot reports about itself, kept current from the watch connection."""

    def __init__(self, url: str) -> None:
        """`url`: a `sim.mavlink_link` URL (BadUrl if it is not one)."""
        self.link = MavlinkLink(url, self.handle, self._on_connect)
        self.home: tuple[float, float, float] | None = (
            None  # first HOME_POSITION: lat, lon, alt MSL
        )
        self.latest_home: tuple[float, float, float] | None = None
        self.sample: Sample | None = None
        self.truth: tuple[float, float, float] | None = None  # SIMSTATE: lat, lon, wall time
        self.attitude = (0.0, 0.0, 0.0)
        self.armed = False
        self.battery_pct: float | None = None
        self.landed_state: int | None = None
        self._landed_state_wall = 0.0
        self.target = (1, 1)
        self._home_event = asyncio.Event()
        self._task: asyncio.Task[None] | None = None
        self._asked_wall = 0.0

    async def start(self) -> None:
        """Connect and keep the streams coming."""
        await self.link.start()
        self._task = asyncio.create_task(self._keep_up(), name="follower")

    async def stop(self) -> None:
        """Stop watching."""
        await cancel_and_wait([self._task])
        await self.link.stop()

    async def wait_home(self, timeout_s: float) -> tuple[float, float, float]:
        """The vehicle's home (lat, lon, alt MSL); TimeoutError when none came within `timeout_s`."""
        await asyncio.wait_for(self._home_event.wait(), timeout_s)
        assert self.home is not None
        return self.home

    def position(self) -> tuple[float, float, float] | None:
        """Where the vehicle is: lat, lon and the wall time of the reading — a SITL's own truth
        (SIMSTATE) while it comes, else the autopilot's estimate (None before either)."""
        t, s = self.truth, self.sample
        if t is not None and time.monotonic() - t[2] < TRUTH_FRESH_S:
            return t
        return None if s is None else (s.lat, s.lon, s.wall)

    def landed(self) -> bool | None:
        """On the ground? (None before the first position.) See the module docstring."""
        if (
            self.landed_state is not None
            and time.monotonic() - self._landed_state_wall < EXT_STATE_FRESH_S
        ):
            return self.landed_state == ON_GROUND
        s = self.sample
        if s is None:
            return None
        return s.rel_alt < LANDED_ALT_M and abs(s.vd) < LANDED_VZ_MPS

    # --- requests ----------------------------------------------------------------------------
    def _on_connect(self) -> None:
        self._ask_streams()

    def _command(self, command: int, *params: float) -> None:
        p = [*params, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0][:7]
        self.link.send(mavlink.MAVLink_command_long_message(*self.target, command, 0, *p))

    def _ask_streams(self) -> None:
        self._asked_wall = time.monotonic()
        for stream_id, rate in DATA_STREAMS:
            self.link.send(
                mavlink.MAVLink_request_data_stream_message(*self.target, stream_id, rate, 1)
            )
        for msg_id, hz in INTERVALS_HZ.items():
            self._command(CMD_SET_MESSAGE_INTERVAL, msg_id, 1e6 / hz)

    def _ask_home(self) -> None:
        self._command(CMD_REQUEST_MESSAGE, HOME_POSITION)
        self._command(CMD_GET_HOME_POSITION)

    async def _keep_up(self) -> None:
        while True:
            self.link.send(mavlink.MAVLink_heartbeat_message(18, 8, 0, 0, 0, 3))  # onboard ctrl
            now = time.monotonic()
            silent = self.sample is None or now - self.sample.wall > SILENT_S
            if self.link.is_connected and silent and now - self._asked_wall > SILENT_S:
                self._ask_streams()
            if self.link.is_connected and self.home is None:
                self._ask_home()
            await asyncio.sleep(HOME_ASK_S)

    # --- input -------------------------------------------------------------------------------
    def handle(self, msg: Any) -> None:
        """Take in one message from the vehicle."""
        kind = msg.get_type()
        if kind == "HEARTBEAT":
            if msg.type != 6 and msg.autopilot != 8:  # a vehicle, not a GCS or a companion
                self.target = (msg.get_srcSystem(), msg.get_srcComponent())
                self.armed = bool(msg.base_mode & 128)
        elif kind == "GLOBAL_POSITION_INT":
            self.sample = Sample(
                msg.lat / 1e7, msg.lon / 1e7, msg.relative_alt / 1000.0,
                msg.vx / 100.0, msg.vy / 100.0, msg.vz / 100.0, time.monotonic(),
            )  # fmt: skip
        elif kind == "ATTITUDE":
            self.attitude = (msg.roll, msg.pitch, msg.yaw)
        elif kind == "SIMSTATE":
            self.truth = (msg.lat / 1e7, msg.lng / 1e7, time.monotonic())
        elif kind == "HOME_POSITION":
            self.latest_home = (msg.latitude / 1e7, msg.longitude / 1e7, msg.altitude / 1000.0)
            if self.home is None:
                self.home = self.latest_home
                log.info("follower: the vehicle's home (the pad) is %s", self.home)
                self._home_event.set()
        elif kind == "EXTENDED_SYS_STATE":
            self.landed_state, self._landed_state_wall = msg.landed_state, time.monotonic()
        elif kind == "SYS_STATUS" and msg.battery_remaining >= 0:
            self.battery_pct = float(msg.battery_remaining)


class FollowerPart:
    """The followed vehicle as a world part: its pose for the sensors, its weight on the base's scale.

    `pose()` is the `Pose` the camera and the IR sensor take: (north, east, camera height above
    the pad, roll, pitch, yaw) relative to the pad centre, `seat_height_m` being the camera's
    height when the vehicle sits on the pad.
    """

    name = "follower"

    def __init__(
        self,
        follower: Follower,
        seat_height_m: float,
        speed: float = 1.0,
        mass_g: float = 1450.0,
        pad_radius_m: float = 0.6,
        contacts_tolerance_m: float = 0.05,
    ) -> None:
        self.follower = follower
        self.seat_height_m = seat_height_m
        self.speed = speed  # the autopilot's simulated seconds per wall second
        self.mass_g = mass_g
        self.pad_radius_m = pad_radius_m
        self.contacts_tolerance_m = contacts_tolerance_m
        self.base: Any = None
        self.pad: GeoOrigin | None = None
        self._load: tuple[bool, bool] | None = None
        self._landed = False
        self._flown = False
        self._battery_told = False

    async def start(self, world: Any) -> None:
        """Take the world's base (placed at the vehicle's home); the follower is already watching."""
        self.base = world.base
        self.pad = GeoOrigin(*world.base.pad_geodetic)

    async def stop(self) -> None:
        """Stop watching the vehicle."""
        await self.follower.stop()

    def pose(self) -> Pose:
        """The vehicle's reported pose relative to the pad centre (sitting on it before any report)."""
        s, pad, where = self.follower.sample, self.pad, self.follower.position()
        if s is None or pad is None or where is None:
            return (0.0, 0.0, self.seat_height_m, 0.0, 0.0, 0.0)
        now = time.monotonic()
        dt, dt_h = (
            min(max(0.0, (now - w) * self.speed), MAX_EXTRAPOLATION_S) for w in (s.wall, where[2])
        )
        n, e, _ = pad.to_ned(where[0], where[1], pad.alt)
        up = max(0.0, s.rel_alt - s.vd * dt)
        return (n + s.vn * dt_h, e + s.ve * dt_h, self.seat_height_m + up, *self.follower.attitude)

    def pad_distance(self) -> float | None:
        """Horizontal distance of the vehicle (`Follower.position`) from the pad centre (None
        before any)."""
        where, pad = self.follower.position(), self.pad
        if where is None or pad is None:
            return None
        n, e, _ = pad.to_ned(where[0], where[1], pad.alt)
        return math.hypot(n, e)

    def step(self, dt_sim: float) -> None:
        """Put the vehicle's mass on the scale when it lands on the pad, take it off when it leaves."""
        landed, dist = self.follower.landed(), self.pad_distance()
        if landed is None or dist is None or self.base is None:
            return
        load = self._judge(landed, dist)
        self._landed = landed
        pct = self.follower.battery_pct
        if load != self._load:
            self._load, self._battery_told = load, False
            log.info(
                "follower: %s, %.3f m from the pad centre",
                "seated on the pad" if load[1] else "on the pad" if load[0] else "off the pad",
                dist,
            )
            self.base.set_pad_load(self.mass_g if load[0] else 0.0, load[1])
            if not load[1]:
                self.base.set_uav_battery(None)
        if load[1] and not self._battery_told and pct is not None:
            self._battery_told = True  # the charger takes over the battery from here
            self.base.set_uav_battery(pct / 100.0)

    def _judge(self, landed: bool, dist: float) -> tuple[bool, bool]:
        """(on the pad, contacts seated). Judged at touchdown and held while the vehicle stays
        landed: a vehicle standing still does not move with the noise of its position estimate.
        Before its first flight it stands where it booted, its home, which is the pad."""
        if not landed:
            self._flown = True
            return (False, False)
        if self._landed and self._load is not None:
            return self._load
        if not self._flown:
            return (True, True)
        return (dist <= self.pad_radius_m, dist <= self.contacts_tolerance_m)

    def status(self) -> dict[str, Any]:
        """What the world believes about the followed vehicle (GET /follower)."""
        f = self.follower
        return {
            "url": f.link.url,
            "connected": f.link.is_connected,
            "messages": f.link.received_count,
            "home": f.home,
            "latest_home": f.latest_home,
            "pose": self.pose() if f.sample is not None else None,
            "pad_distance_m": self.pad_distance(),
            "landed": f.landed(),
            "armed": f.armed,
            "battery_pct": f.battery_pct,
            "on_pad": bool(self._load and self._load[0]),
        }

    def routers(self) -> list[Any]:
        """GET /follower."""
        from fastapi import APIRouter

        router = APIRouter(tags=["follower"])
        router.add_api_route("/follower", self.status, methods=["GET"])
        return [router]
