"""Flying the simulated autopilot through the adapter over real MAVLink (UDP, and one over TCP)."""

from __future__ import annotations

import asyncio
import contextlib
import math
from collections.abc import AsyncIterator

import pytest

from asset_agent.autopilot import Autopilot, CommandRejected, items_from_dicts
from asset_agent.autopilot.params import set_param
from asset_agent.autopilot.state import Notification, UavState
from asset_agent.events import EventTracker
from asynckit.tasks import cancel_and_wait
from protocol.rtcm import build_frame
from sim.vehicle.geo import GeoOrigin
from sim.vehicle.server import VehicleServer
from sim.vehicle.standalone import OpenPad
from tests.asset_agent.conftest import fast_config
from tests.polling import eventually


@contextlib.asynccontextmanager
async def corrections(ap: Autopilot, period_s: float = 0.2) -> AsyncIterator[None]:
    """Keep injecting valid RTCM3 frames (1005 + an MSM-sized filler) while the block runs."""

    async def feed() -> None:
        while True:
            ap.inject_rtcm(build_frame(bytes([0x3E, 0xD0]) + bytes(17)))  # type 1005
            ap.inject_rtcm(build_frame(bytes([0x43, 0x70]) + bytes(300)))  # type 1079, fragmented
            await asyncio.sleep(period_s)

    task = asyncio.create_task(feed())
    try:
        yield
    finally:
        task.cancel()
        with contextlib.suppress(asyncio.CancelledError):
            await task


def drain(q: asyncio.Queue[Notification]) -> list[Notification]:
    """Everything queued so far."""
    out = []
    while not q.empty():
        out.append(q.get_nowait())
    return out


@pytest.mark.slow
async def test_fly_mission_rtl_and_land_on_the_pad(
    autopilot: Autopilot, vehicle: VehicleServer, pad: OpenPad
) -> None:
    origin = GeoOrigin(*pad.pad_geodetic)
    wp1 = origin.to_geodetic(40.0, 0.0, 0.0)
    wp2 = origin.to_geodetic(40.0, 30.0, 0.0)
    mission = [
        {"command": 22, "frame": 3, "params": [0, 0, 0, 0], "lat": 0, "lon": 0, "alt": 12},
        {"command": 178, "frame": 2, "params": [1, 12, -1, 0], "lat": 0, "lon": 0, "alt": 0},
        {
            "command": 16,
            "frame": 3,
            "params": [0, 0, 0, 0],
            "lat": wp1[0],
            "lon": wp1[1],
            "alt": 15,
        },
        {
            "command": 19,
            "frame": 3,
            "params": [2, 0, 0, 0],
            "lat": wp2[0],
            "lon": wp2[1],
            "alt": 15,
        },
        {"command": 20, "frame": 2, "params": [0, 0, 0, 0], "lat": 0, "lon": 0, "alt": 0},
    ]
    notes = autopilot.subscribe()
    tracker = EventTracker()
    events: list[str] = []

    async def watch() -> None:
        while True:
            events.extend(e.kind for e in tracker.update(autopilot.state))
            await asyncio.sleep(0.01)

    watcher = asyncio.create_task(watch())
    async with corrections(autopilot):
        await eventually(lambda: autopilot.state.fix_type == 6, 15, "RTK fixed")
        await autopilot.upload_mission(items_from_dicts(mission))
        assert pad.mass_g > 0 and pad.contacts_seated  # starts seated on the pad
        await autopilot.start_mission()
        await eventually(lambda: autopilot.state.armed, 5, "armed")
        await eventually(lambda: autopilot.state.in_air, 10, "in the air")
        assert pad.mass_g == 0 and not pad.contacts_seated
        await eventually(lambda: vehicle.copter.dyn.state.altitude > 10, 20, "climb")
        await eventually(lambda: not autopilot.state.armed, 60, "landed and disarmed")
    truth = vehicle.copter.dyn.state
    assert truth.landed
    notifications = drain(notes)
    reached = [n for n in notifications if n.kind == "item_reached"]
    assert [n.index for n in reached[:4]] == [0, 2, 3, 4]  # takeoff, two waypoints, RTL (change
    # speed is not nav); each carries the state it was heard in, still on that item (the
    # autopilot moves on after it says so): EventTracker.feed orders the events by these
    assert [n.state and n.state.mission_current for n in reached[:4]] == [0, 2, 3, 4]
    dist = vehicle.copter.pad_distance()
    sigma = vehicle.copter.gnss.params.sigma_fixed_m
    assert dist <= 4 * sigma + 0.02, f"landed {dist:.3f} m from the pad centre"
    assert pad.mass_g == vehicle.copter.config.dynamics.mass_g
    assert pad.contacts_seated == (dist <= vehicle.copter.config.contacts_tolerance_m)
    await eventually(lambda: autopilot.state.landed_state == "ON_GROUND", 5, "ON_GROUND")
    assert autopilot.state.mission_state == "COMPLETE"
    assert autopilot.state.battery_pct is not None and autopilot.state.battery_pct < 100
    await eventually(lambda: "mission_finished" in events, 5, "mission_finished event")
    await cancel_and_wait([watcher])
    # the last state too: the waits above return at once on a condition already true, without
    # letting the watcher's 10 ms poll run after the disarm (under load it missed "disarmed")
    events.extend(e.kind for e in tracker.update(autopilot.state))
    for kind in ("armed", "took_off", "landing", "landed", "mission_finished", "disarmed"):
        assert events.count(kind) == 1, (kind, events)
    assert events.index("armed") < events.index("took_off") < events.index("landing")
    assert events.index("landing") < events.index("landed") <= events.index("disarmed")
    waypoint_events = [e for n in notifications for e in tracker.notification(n)]
    assert [e.detail["index"] for e in waypoint_events][:4] == [0, 2, 3, 4]


@pytest.mark.slow
async def test_guided_takeoff_velocity_and_abort_over_tcp(vehicle: VehicleServer) -> None:
    ap = Autopilot(fast_config(f"tcp:127.0.0.1:{vehicle.tcp_port}"))
    await ap.start()
    try:
        await ap.wait_link(10)
        await eventually(lambda: ap.state.fix_type >= 3, 10, "fix")
        await ap.set_mode("GUIDED")
        await ap.arm()
        await ap.takeoff(8)
        await eventually(lambda: (ap.state.alt_rel or 0) > 7.5, 20, "takeoff altitude")
        start_n = vehicle.copter.dyn.state.position[0]
        ap.send_velocity_ned(3.0, 0.0, 0.0)
        await eventually(
            lambda: vehicle.copter.dyn.state.position[0] > start_n + 5, 20, "moving north"
        )
        ap.send_position_ned(0.0, 0.0, -6.0)
        await eventually(lambda: vehicle.copter.dyn.state.position[0] < 1.0, 20, "back over home")
        await ap.pause()
        await eventually(lambda: ap.state.mode == "BRAKE", 5, "BRAKE")
        assert await ap.abort() == "rtl"
        await eventually(lambda: ap.state.mode == "RTL", 5, "RTL")
        await eventually(lambda: not ap.state.armed, 60, "landed and disarmed")
        assert await ap.abort() == "disarmed"
        # without corrections the landing is only as good as a 3D fix
        sigma = vehicle.copter.gnss.params.sigma_3d_m
        assert vehicle.copter.pad_distance() <= 4 * sigma
    finally:
        await ap.close()


async def test_prearm_failure_gives_a_typed_error(
    autopilot: Autopilot, vehicle: VehicleServer
) -> None:
    vehicle.copter.faults.prearm_failure = "Compass not calibrated"
    await autopilot.set_mode("GUIDED")
    with pytest.raises(CommandRejected) as info:
        await autopilot.arm()
    assert info.value.result_name == "FAILED"
    assert info.value.detail == "PreArm: Compass not calibrated"
    assert not vehicle.copter.armed


async def test_closed_base_blocks_arming(
    autopilot: Autopilot, vehicle: VehicleServer, pad: OpenPad
) -> None:
    pad.open = False
    with pytest.raises(CommandRejected) as info:
        await autopilot.arm()
    assert "PreArm: Base closed" in info.value.detail
    pad.open = True
    await autopilot.set_mode("RTL")
    with pytest.raises(CommandRejected) as info:
        await autopilot.arm()
    assert (
        info.value.detail == "PreArm: Mode not armable"
    )  # this attempt's reason, not the last one


async def test_silent_autopilot_times_out_a_command(
    autopilot: Autopilot, vehicle: VehicleServer
) -> None:
    from asset_agent.autopilot import AutopilotTimeout

    vehicle.copter.faults.mute_until = math.inf
    with pytest.raises(AutopilotTimeout):
        await autopilot.command(400, 1, ack_timeout_s=0.2, retries=1)
    assert not vehicle.copter.armed


async def test_low_battery_blocks_arming(autopilot: Autopilot, vehicle: VehicleServer) -> None:
    vehicle.copter.dyn.set_battery(12.0)
    await eventually(lambda: autopilot.state.battery_pct == 12, 5, "battery report")
    with pytest.raises(CommandRejected) as info:
        await autopilot.arm()
    assert "Battery" in info.value.detail


async def test_nacked_commands(autopilot: Autopilot, vehicle: VehicleServer) -> None:
    with pytest.raises(CommandRejected) as info:
        await autopilot.takeoff(10)  # not armed
    assert info.value.result_name == "FAILED" and info.value.command == 22
    with pytest.raises(CommandRejected) as info:
        await autopilot.command(183, 9, 1500)  # DO_SET_SERVO: not simulated
    assert info.value.result_name == "UNSUPPORTED"
    await set_param(autopilot, "DISARM_DELAY", 0)  # the autopilot would not disarm by itself
    with pytest.raises(CommandRejected):
        await autopilot.start_mission()  # no mission: MISSION_START fails after arming
    # and the adapter disarmed again (acknowledged before the error came back): no motor left
    # idling on the pad
    assert not vehicle.copter.armed


async def test_auto_without_takeoff_item_is_refused_on_the_ground(
    autopilot: Autopilot, vehicle: VehicleServer
) -> None:
    wp = {
        "command": 16,
        "frame": 3,
        "params": [0, 0, 0, 0],
        "lat": 41.1781,
        "lon": -8.596,
        "alt": 10,
    }
    await autopilot.upload_mission(items_from_dicts([wp]))
    await set_param(autopilot, "DISARM_DELAY", 0)  # the autopilot would not disarm by itself
    with pytest.raises(CommandRejected) as info:
        await autopilot.start_mission()
    assert "Missing Takeoff" in info.value.detail
    assert not vehicle.copter.armed  # disarmed again after the refused start


@pytest.mark.slow
async def test_rtk_corrections_turn_the_fix_to_rtk_fixed_and_bad_crc_does_not(
    autopilot: Autopilot, vehicle: VehicleServer
) -> None:
    gnss = vehicle.copter.gnss
    bad = bytearray(
        build_frame(bytes([0x43, 0x70]) + bytes(354))
    )  # 360 bytes: ends with an empty fragment
    bad[-1] ^= 0xFF
    for _ in range(10):
        assert autopilot.inject_rtcm(bytes(bad)) == 3
    await eventually(lambda: gnss.bad_frames >= 10, 5, "bad frames seen")
    assert gnss.valid_frames == 0
    assert gnss.fix_type(vehicle.copter.wall) == 3
    # a 1029-byte frame is longer than one GPS_RTCM_DATA message (719 bytes): sent in two
    assert autopilot.inject_rtcm(build_frame(bytes(1023))) == 4 + 2
    await eventually(lambda: gnss.valid_frames == 1, 5, "the long frame re-assembled")
    seen_fixes: set[int] = set()

    def record() -> bool:
        seen_fixes.add(autopilot.state.fix_type)
        return autopilot.state.fix_type == 6

    async with corrections(autopilot, 0.1):
        await eventually(record, 15, "RTK fixed")
    assert 5 in seen_fixes  # float on the way to fixed
    assert autopilot.state.fix_name == "RTK_FIXED"
    assert vehicle.copter.reading.h_acc_m < 0.05
    await eventually(lambda: autopilot.state.fix_type == 3, 15, "back to 3D once corrections stop")


@pytest.mark.slow
async def test_landing_target_frames(autopilot: Autopilot, vehicle: VehicleServer) -> None:
    copter = vehicle.copter
    await autopilot.set_mode("GUIDED")
    await autopilot.arm()
    await autopilot.takeoff(10)
    await eventually(lambda: copter.dyn.state.altitude > 9.5, 20, "takeoff")
    await eventually(lambda: autopilot.state.armed, 5, "armed in the HEARTBEAT")
    texts = autopilot.subscribe()
    autopilot.send_landing_target(0.0, 0.0, 10.0, frame=1)  # MAV_FRAME_LOCAL_NED
    await eventually(
        lambda: any("Frame not supported" in n.text for n in drain_into(texts, seen)),
        5,
        "rejection",
    )
    assert copter.precland.accepted == 0 and copter.precland.rejected == 1
    # the landing target: 4 m east of where the vehicle hovers (ground truth)
    n0, e0, _ = copter.dyn.state.position
    target = (n0, e0 + 4.0)
    await autopilot.land()

    async def sensor() -> None:
        while True:
            s = copter.dyn.state
            to_target = (target[0] - s.position[0], target[1] - s.position[1], max(s.altitude, 0.1))
            x, y, z = ned_to_body(to_target, s.roll, s.pitch, s.yaw)
            # a camera's angles in the body frame; ArduPilot: los = (-tan(angle_y), tan(angle_x), 1)
            autopilot.send_landing_target(math.atan2(y, z), -math.atan2(x, z), frame=12)
            await asyncio.sleep(0.02)

    task = asyncio.create_task(sensor())
    try:
        await eventually(lambda: not autopilot.state.armed, 60, "landed")
    finally:
        task.cancel()
    s = copter.dyn.state
    miss = math.hypot(s.position[0] - target[0], s.position[1] - target[1])
    assert miss < 0.3, f"landed {miss:.2f} m from the target"
    assert copter.precland.accepted > 10


seen: list[Notification] = []


def ned_to_body(
    v: tuple[float, float, float], roll: float, pitch: float, yaw: float
) -> tuple[float, float, float]:
    """Rotate a NED vector into the body FRD frame (the transpose of Rz(yaw) Ry(pitch) Rx(roll))."""
    n, e, d = v
    cy, sy = math.cos(yaw), math.sin(yaw)
    n, e = cy * n + sy * e, -sy * n + cy * e  # undo yaw
    cp, sp = math.cos(pitch), math.sin(pitch)
    n, d = cp * n - sp * d, sp * n + cp * d  # undo pitch
    cr, sr = math.cos(roll), math.sin(roll)
    e, d = cr * e + sr * d, -sr * e + cr * d  # undo roll
    return n, e, d


def drain_into(q: asyncio.Queue[Notification], into: list[Notification]) -> list[Notification]:
    """Move queued notifications into `into` and return all of them."""
    into.extend(drain(q))
    return into


async def test_link_loss_and_recovery(autopilot: Autopilot, vehicle: VehicleServer) -> None:
    notes = autopilot.subscribe()
    vehicle.copter.faults.mute_until = math.inf
    await eventually(lambda: not autopilot.link_up, 10, "link lost")
    from asset_agent.autopilot import LinkLost

    with pytest.raises(LinkLost):
        await autopilot.arm()
    vehicle.copter.faults.mute_until = 0.0
    await eventually(lambda: autopilot.link_up, 10, "link recovered")
    kinds = [n.kind for n in drain(notes) if n.kind.startswith("link")]
    assert kinds == ["link_lost", "link_recovered"]


@pytest.mark.slow
async def test_set_message_interval_is_honoured(
    autopilot: Autopilot, vehicle: VehicleServer
) -> None:
    await autopilot.set_message_interval(30, 25.0)  # ATTITUDE at 25 Hz
    link = vehicle.udp_link
    assert link is not None
    assert link.streams.intervals[30] == pytest.approx(0.04)
    await autopilot.set_message_interval(30, 0)  # stop ATTITUDE
    assert link.streams.intervals[30] is None
    with autopilot.tap(lambda m: m.get_type() in ("ATTITUDE", "HEARTBEAT")) as q:
        heartbeats = 0
        attitudes = 0
        while heartbeats < 3:
            msg = await asyncio.wait_for(q.get(), 5)
            heartbeats += msg.get_type() == "HEARTBEAT"
            attitudes += msg.get_type() == "ATTITUDE"
    assert attitudes <= 1  # at most one already in flight when the ACK came back
    await autopilot.set_message_interval(30, 10.0)
    with autopilot.tap(lambda m: m.get_type() == "ATTITUDE") as q:
        await asyncio.wait_for(q.get(), 5)


@pytest.mark.slow
async def test_battery_failsafe_returns_home(autopilot: Autopilot, vehicle: VehicleServer) -> None:
    tracker = EventTracker()
    tracker.update(autopilot.state)
    await autopilot.set_mode("GUIDED")
    await autopilot.arm()
    await autopilot.takeoff(5)
    await eventually(lambda: autopilot.state.in_air and autopilot.state.armed, 10, "flying")
    events = [e.kind for e in tracker.update(autopilot.state)]
    vehicle.copter.dyn.set_battery(14.0)
    await eventually(
        lambda: autopilot.state.mode == "RTL" and autopilot.state.failsafe, 10, "failsafe RTL"
    )
    await eventually(
        lambda: autopilot.state.battery_pct is not None and autopilot.state.battery_pct < 15, 5
    )
    events += [e.kind for e in tracker.update(autopilot.state)]
    assert {"armed", "took_off", "failsafe", "low_battery"} <= set(events)
    assert "Battery Failsafe" in autopilot.statustexts
    await eventually(lambda: not autopilot.state.armed, 60, "landed at home")
    assert vehicle.copter.pad_distance() <= 4 * vehicle.copter.gnss.params.sigma_3d_m
    assert isinstance(tracker.prev, UavState)


@pytest.mark.slow
async def test_unreachable_autopilot_is_a_typed_error() -> None:
    import socket

    from asset_agent.autopilot import LinkLost

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]  # bound, never listening: connections are refused
        ap = Autopilot(fast_config(f"tcp:127.0.0.1:{port}"))
        with pytest.raises(LinkLost):
            await ap.start()
