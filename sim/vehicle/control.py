"""The vehicle's part of the world's HTTP control interface: ground truth and fault injection."""

from __future__ import annotations

import math
import time
from typing import Any

from fastapi import APIRouter
from pydantic import BaseModel, Field

from sim.vehicle.constants import MODE_NAMES
from sim.vehicle.server import VehicleServer


class PrearmFault(BaseModel):
    """Make arming fail with "PreArm: <reason>"; null clears it."""

    reason: str | None = Field(default="Injected failure", max_length=40)


class GnssBias(BaseModel):
    """A steady GNSS position error, metres north and east."""

    north_m: float = Field(default=0.0, ge=-100, le=100)
    east_m: float = Field(default=0.0, ge=-100, le=100)


class MuteFault(BaseModel):
    """Stop answering MAVLink for `seconds` wall seconds; null means until cleared."""

    seconds: float | None = Field(default=None, gt=0)


class Toggle(BaseModel):
    """Turn a fault on or off."""

    enabled: bool = True


class LostAcks(BaseModel):
    """Lose the next `count` COMMAND_ACKs (the commands are carried out all the same)."""

    count: int = Field(ge=0, le=100)


class StaleMissionFault(BaseModel):
    """Deliver the previous mission's end (its last MISSION_CURRENT and MISSION_ITEM_REACHED)
    again, late or early, after the next upload (sim/vehicle/stale.py)."""

    enabled: bool = True
    before_ack: bool = Field(default=True, description="just before the upload's MISSION_ACK")
    on_arming: bool = Field(default=True, description="when the vehicle arms after the upload")
    on_start: bool = Field(default=True, description="right after MISSION_START (AUTO)")
    repeat: int = Field(default=1, ge=1, le=20, description="copies each time")


class BatteryOverride(BaseModel):
    """Set the battery level in percent."""

    percent: float = Field(ge=0, le=100)


def truth(server: VehicleServer) -> dict[str, Any]:
    """The vehicle's ground truth and what the autopilot believes, as JSON-ready values."""
    c = server.copter
    s = c.dyn.state
    lat, lon, alt = c.origin.to_geodetic(*s.position)
    return {
        "sim_time_s": c.t,
        "position_ned_m": list(s.position),
        "velocity_ned_mps": list(s.velocity),
        "geodetic": {"lat": lat, "lon": lon, "alt_msl_m": alt},
        "attitude_deg": {
            "roll": math.degrees(s.roll),
            "pitch": math.degrees(s.pitch),
            "yaw": math.degrees(s.yaw) % 360,
        },
        "altitude_m": s.altitude,
        "landed": s.landed,
        "armed": c.armed,
        "mode": MODE_NAMES.get(c.mode, str(c.mode)),
        "distance_to_pad_m": c.pad_distance(),
        "battery_pct": s.battery_pct,
        "gnss": {
            "fix_type": c.reading.fix_type,
            "error_ned_m": list(c.reading.error_ned),
            "valid_rtcm_frames": c.gnss.valid_frames,
            "bad_rtcm_frames": c.gnss.bad_frames,
        },
        "ports": {"mavlink_tcp": server.tcp_port, "mavlink_udp": server.udp_port},
    }


def faults(server: VehicleServer) -> dict[str, Any]:
    """The active faults."""
    f = server.copter.faults
    remaining = f.mute_until - time.monotonic()
    return {
        "prearm_failure": f.prearm_failure,
        "muted": server.muted(),
        "mute_remaining_s": None if math.isinf(remaining) else max(0.0, remaining),
        "drop_mission": f.drop_mission,
        "drop_acks": f.drop_acks,
        "no_gnss_fix": not server.copter.gnss.has_fix,
        "gnss_bias_ne_m": list(server.copter.gnss.bias_ne_m),
        "stale_mission": f.stale_mission.status(),
    }


def vehicle_router(server: VehicleServer, prefix: str = "/vehicle") -> APIRouter:
    """Routes for ground truth and fault injection, under `prefix`."""
    router = APIRouter(prefix=prefix, tags=["vehicle"])
    c = server.copter

    @router.get("/truth")
    async def get_truth() -> dict[str, Any]:
        """Ground truth: true position, velocity, attitude, landed, distance to the pad centre."""
        return truth(server)

    @router.get("/faults")
    async def get_faults() -> dict[str, Any]:
        """The injected faults."""
        return faults(server)

    @router.post("/faults/prearm")
    async def fail_prearm(body: PrearmFault) -> dict[str, Any]:
        """Make the pre-arm checks fail (null reason clears)."""
        c.faults.prearm_failure = body.reason
        return faults(server)

    @router.post("/faults/mute")
    async def mute(body: MuteFault) -> dict[str, Any]:
        """Stop answering MAVLink for N seconds or until cleared."""
        c.faults.mute_until = math.inf if body.seconds is None else time.monotonic() + body.seconds
        return faults(server)

    @router.delete("/faults/mute")
    async def unmute() -> dict[str, Any]:
        """Answer MAVLink again."""
        c.faults.mute_until = 0.0
        return faults(server)

    @router.post("/faults/drop_mission")
    async def drop_mission(body: Toggle) -> dict[str, Any]:
        """Ignore every mission-protocol message."""
        c.faults.drop_mission = body.enabled
        return faults(server)

    @router.post("/faults/drop_acks")
    async def drop_acks(body: LostAcks) -> dict[str, Any]:
        """Lose the next N COMMAND_ACKs, as a lossy radio does: the commands still act."""
        c.faults.drop_acks = body.count
        return faults(server)

    @router.post("/faults/stale_mission")
    async def stale_mission(body: StaleMissionFault) -> dict[str, Any]:
        """Replay the previous mission's end after the next upload: before its MISSION_ACK, at
        the arming, right after MISSION_START, each `repeat` times."""
        stale = c.faults.stale_mission
        stale.enabled, stale.repeat = body.enabled, body.repeat
        stale.before_ack, stale.on_arming, stale.on_start = (
            body.before_ack,
            body.on_arming,
            body.on_start,
        )
        return faults(server)

    @router.post("/faults/no_gnss_fix")
    async def no_fix(body: Toggle) -> dict[str, Any]:
        """Lose (or regain) the GNSS fix."""
        c.gnss.has_fix = not body.enabled
        return faults(server)

    @router.post("/faults/gnss_bias")
    async def gnss_bias(body: GnssBias) -> dict[str, Any]:
        """Add a steady error to the reported position (the vehicle then lands that far off)."""
        c.gnss.bias_ne_m = (body.north_m, body.east_m)
        return truth(server)

    @router.post("/battery")
    async def battery(body: BatteryOverride) -> dict[str, Any]:
        """Override the battery level."""
        c.dyn.set_battery(body.percent)
        return truth(server)

    @router.post("/faults/clear")
    async def clear() -> dict[str, Any]:
        """Clear every fault."""
        c.faults.prearm_failure = None
        c.faults.mute_until = 0.0
        c.faults.drop_mission = False
        c.faults.drop_acks = 0
        c.faults.stale_mission.enabled = False
        c.gnss.has_fix = True
        c.gnss.bias_ne_m = (0.0, 0.0)
        return faults(server)

    return router
