"""The simulated autopilot's ArduPilot habits (sim/vehicle/habits.py), seen by a raw MAVLink peer,
and its storage model checked against AP_Mission's packing."""

from __future__ import annotations

import math
import time

import pytest

from sim.vehicle import mission as ms
from sim.vehicle.__main__ import habits_of, parse_args, setup
from sim.vehicle.constants import LAND
from sim.vehicle.copter import CopterConfig
from sim.vehicle.habits import PROFILES, Habits, profile, stored
from sim.vehicle.server import run_vehicle
from sim.vehicle.standalone import OpenPad
from sim.vehicle.streams import ATTITUDE, GLOBAL_POSITION_INT, HEARTBEAT, StreamScheduler
from tests.sim.test_vehicle_mavlink import Peer

NAN = math.nan


def test_storage_packs_params_as_ap_mission_does():
    wp = stored(ms.Item(1, 6, 16, 2.7, 3.0, 1.0, NAN, 411780000, -85960000, 20.129))
    assert (wp.param1, wp.param2, wp.param3, wp.param4) == (2.0, 0.0, 0.0, 0.0)
    assert (wp.frame, wp.x, wp.y, wp.z, wp.autocontinue) == (3, 411780000, -85960000, 20.12, 1)
    takeoff = stored(ms.Item(1, 3, 22, 0, 0, 0, NAN, 1, 2, 20))
    assert takeoff.param4 == 0.0  # issue 13: the QGC plan's null yaw came back 0
    land = stored(ms.Item(1, 3, 21, 0, 0, 0, 0, 1, 2, 0))
    assert land.param4 == 1.0  # the loiter direction: issue 13's "item 1 param4"
    speed = stored(ms.Item(1, 2, 178, 1, 5.5, -1, 7))
    assert (speed.param1, speed.param2, speed.param3, speed.param4, speed.frame) == (
        1,
        5.5,
        -1,
        0,
        0,
    )
    rtl = stored(ms.Item(1, 3, 20, 1, 2, 3, 4, 5, 6, 7.0))
    assert (rtl.param1, rtl.x, rtl.y, rtl.z) == (0.0, 0, 0, 0.0)
    jump = stored(ms.Item(1, 2, 177, 3.9, -1, 0, 0))
    assert (jump.param1, jump.param2) == (3.0, -1.0)


def test_profiles_and_the_command_line():
    assert not PROFILES["ardupilot-3.7"].message_interval
    assert not PROFILES["ardupilot-3.7"].extended_sys_state
    assert PROFILES["ardupilot-4"].message_interval and PROFILES["ardupilot-4"].boot_s >= 30
    assert habits_of(parse_args([])) == Habits()  # no profile: the historic defaults
    h = habits_of(parse_args(["--autopilot-profile", "ardupilot-3.7", "--boot-s", "3"]))
    assert h.name == "ardupilot-3.7" and h.boot_s == 3.0 and not h.message_interval
    h = habits_of(parse_args(["--no-message-interval", "--keep-params"]))
    assert not h.message_interval and not h.ardupilot_storage and h.extended_sys_state
    with pytest.raises(ValueError, match="unknown autopilot profile"):
        profile("px4")
    assert setup(parse_args(["--uptime-s", "86400"])).copter.time_boot_ms == 86_400_000
    with pytest.raises(SystemExit):  # "--uptime-s must not be negative"
        parse_args(["--uptime-s", "-1"])


@pytest.mark.parametrize("name", ["ardupilot-4", "ardupilot-3.7"])
def test_a_data_stream_turned_on_comes_first_as_each_release_sends_it(name: str):
    """4.x puts REQUEST_DATA_STREAM's messages in buckets (first one interval later); 3.x's
    `stream_trigger` sends a stream that was off at its next tick."""
    buckets = PROFILES[name].stream_buckets
    s = StreamScheduler(0.0, quiet=True, at_once=not buckets)
    assert GLOBAL_POSITION_INT not in s.due(10.0)
    s.request_data_stream(6, 1, 1)  # POSITION at 1 Hz
    assert (GLOBAL_POSITION_INT in s.due(10.02)) is not buckets
    assert GLOBAL_POSITION_INT in s.due(11.0)  # one interval on: both


def test_a_message_asked_again_at_its_interval_keeps_its_schedule():
    """ArduPilot 4.x leaves a message in its bucket when asked for the interval it has ("don't
    need to move it"): an agent renegotiating every stream after a link dropout does not pause
    them. Restarted, ATTITUDE would next come at 1.7 s, not 1.0 s."""
    s = StreamScheduler(0.0, quiet=True)
    s.set_interval(ATTITUDE, 500_000)
    assert ATTITUDE in s.due(0.5)
    s.due(0.7)
    s.set_interval(ATTITUDE, 500_000)  # asked again, 0.2 s on
    assert ATTITUDE not in s.due(0.99)
    assert ATTITUDE in s.due(1.0)
    s.set_interval(ATTITUDE, 1_000_000)  # a new interval: a new bucket, one interval on
    assert ATTITUDE not in s.due(1.99)
    assert ATTITUDE in s.due(2.0)


def test_a_message_given_the_interval_of_another_is_sent_with_it():
    """4.x puts a message given an interval that a bucket already has into that bucket: it comes
    with the bucket's next send, not one whole interval after it was asked for; a heartbeat (a
    deferred message, not in a bucket) starts over."""
    s = StreamScheduler(0.0, quiet=True)
    s.set_interval(ATTITUDE, 1_000_000)
    s.due(0.7)
    s.set_interval(GLOBAL_POSITION_INT, 1_000_000.4)  # the same whole milliseconds
    assert {ATTITUDE, GLOBAL_POSITION_INT} <= set(s.due(1.0))
    s.due(1.5)
    s.set_interval(HEARTBEAT, 1_000_000)  # due at 2.0 before
    assert HEARTBEAT not in s.due(2.0)
    assert HEARTBEAT in s.due(2.5)


def test_ardupilot_3x_sends_a_stream_asked_again_on_its_old_count():
    """3.x's `stream_trigger` counts a stream that is on down from its old rate: asked again it
    is not sent at once (only a stream that was off is), then at the new rate."""
    s = StreamScheduler(0.0, quiet=True, at_once=True)
    s.request_data_stream(6, 1, 1)  # POSITION at 1 Hz, off before: at once
    assert GLOBAL_POSITION_INT in s.due(0.02)
    s.request_data_stream(6, 4, 1)  # at 4 Hz, 0.5 s on
    assert GLOBAL_POSITION_INT not in s.due(0.52)
    assert GLOBAL_POSITION_INT in s.due(1.0)  # the old count run out
    assert GLOBAL_POSITION_INT in s.due(1.25)  # then every 0.25 s


@pytest.mark.parametrize("name", ["ardupilot-4", "ardupilot-3.7"])
async def test_a_mode_change_is_told_at_once_by_4x_and_at_the_next_beat_by_3x(name: str):
    """4.x's `Copter::set_mode` sends a HEARTBEAT as soon as the mode is set: a failsafe's RTL
    is known to a companion at once, not up to a second later; the 3.6-era one does not."""
    config = CopterConfig(seed=1, habits=profile(name, boot_s=0.0))
    async with run_vehicle(config=config) as v:
        peer = Peer(f"tcp:127.0.0.1:{v.tcp_port}")
        try:
            await peer.recv("HEARTBEAT")  # a 1 Hz beat just now: the next is ~1 s away
            changed = time.monotonic()
            assert v.copter.set_mode(LAND)  # the autopilot's own change (a failsafe's)
            await peer.recv("HEARTBEAT", custom_mode=LAND, within=3.0)
            told_at_once = time.monotonic() - changed < 0.5
            assert told_at_once is PROFILES[name].mode_heartbeat
        finally:
            peer.conn.close()


@pytest.mark.slow  # waits 2 s to show a message never comes
async def test_ardupilot_37_refuses_message_intervals_but_honours_data_streams():
    config = CopterConfig(seed=1, habits=profile("ardupilot-3.7", boot_s=0.0))
    async with run_vehicle(speed=10, config=config) as v:
        peer = Peer(f"tcp:127.0.0.1:{v.tcp_port}")
        try:
            await peer.recv("HEARTBEAT")
            peer.conn.mav.command_long_send(1, 1, 511, 0, 33, 200000, 0, 0, 0, 0, 0)
            ack = await peer.recv("COMMAND_ACK", command=511)
            assert ack.result == 3  # MAV_RESULT_UNSUPPORTED
            peer.conn.mav.request_data_stream_send(1, 1, 6, 5, 1)  # POSITION at 5 Hz
            await peer.recv("GLOBAL_POSITION_INT")
            peer.conn.mav.request_data_stream_send(1, 1, 0, 2, 1)  # every group
            await peer.recv("SYS_STATUS")
            await peer.recv("MISSION_CURRENT")
            with pytest.raises(AssertionError):
                await peer.recv("EXTENDED_SYS_STATE", within=2.0)
        finally:
            peer.conn.close()


@pytest.mark.slow
async def test_a_quiet_companion_port_sends_only_heartbeats_until_asked():
    config = CopterConfig(seed=1, habits=profile("ardupilot-4", boot_s=0.0))
    async with run_vehicle(speed=10, config=config) as v:
        peer = Peer(f"tcp:127.0.0.1:{v.tcp_port}")
        try:
            await peer.recv("HEARTBEAT")
            with pytest.raises(AssertionError):
                await peer.recv("ATTITUDE", within=1.5)
            peer.conn.mav.command_long_send(1, 1, 511, 0, 30, 100000, 0, 0, 0, 0, 0)
            assert (await peer.recv("COMMAND_ACK", command=511)).result == 0
            await peer.recv("ATTITUDE")
        finally:
            peer.conn.close()


def test_missions_fly_their_speed_and_rtl_flies_wpnav_speed():
    from sim.vehicle.copter import Copter

    c = Copter(OpenPad(), CopterConfig(seed=2))
    lat, lon = round(41.1780 * 1e7), round(-8.5960 * 1e7)
    c.items = [
        c.home_item(),
        ms.Item(1, 3, ms.NAV_TAKEOFF, z=5),
        ms.Item(2, 2, ms.DO_CHANGE_SPEED, param1=1, param2=4.0, param3=-1),
        ms.Item(3, 3, ms.NAV_WAYPOINT, x=lat + 9000, y=lon, z=5),  # 100 m north
        ms.Item(4, 2, ms.NAV_RETURN_TO_LAUNCH),
    ]
    assert c.set_mode(4) and c.arm() == 0 and c.set_mode(3)
    top: dict[str, float] = {}
    for _ in range(8000):
        c.tick(0.05, 0.0)
        c.outbox.clear()
        v = math.hypot(*c.dyn.state.velocity[:2])
        phase = "rtl" if c.guidance.rtl_phase or c.mission_current >= 4 else "mission"
        top[phase] = max(top.get(phase, 0.0), v)
        if not c.armed:
            break
    assert top["mission"] == pytest.approx(4.0, abs=0.3)  # the DO_CHANGE_SPEED
    assert top["rtl"] == pytest.approx(c.config.wp_speed, abs=0.5)  # WPNAV_SPEED, 10 m/s
