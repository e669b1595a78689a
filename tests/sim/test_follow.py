"""The world following an external autopilot (`sim.follow`): a simulated vehicle served on its own
is the external one; the world watches it over its own MAVLink TCP connection and a pymavlink peer
flies it, as the agent would."""

from __future__ import annotations

import contextlib
import math
from collections.abc import AsyncIterator
from typing import Any

import httpx
import pytest
from pymavlink.dialects.v20 import ardupilotmega as mavlink

from aerobase.demo.run import main as demo_main
from aerobase.ports import free_port
from sim.assemble import SEAT_HEIGHT, build
from sim.assemble import main as world_main
from sim.autopilot import parse_args as autopilot_args
from sim.autopilot import setup as autopilot_setup
from sim.follow import Follower, FollowerPart
from sim.mavlink_link import BadUrl, parse_url
from sim.vehicle.copter import CopterConfig
from sim.vehicle.geo import GeoOrigin
from sim.vehicle.gnss import GnssParams
from sim.vehicle.habits import profile
from sim.vehicle.server import run_vehicle
from sim.world import World, WorldConfig
from tests.polling import eventually
from tests.sim.test_vehicle_mavlink import Peer

GUIDED, LAND = 4, 9
MASS_G = 1450.0
SPEED = 20.0


def _config(server, speed: float) -> WorldConfig:
    return WorldConfig.for_tests(
        speed=speed, follow=f"tcp:127.0.0.1:{server.tcp_port}", follow_timeout_s=10
    )


async def _take_off(peer: Peer, alt: float) -> None:
    peer.conn.mav.set_mode_send(1, 1, GUIDED)
    peer.conn.mav.command_long_send(1, 1, 400, 0, 1, 0, 0, 0, 0, 0, 0)  # arm
    await peer.recv("COMMAND_ACK", command=400, result=0)
    peer.conn.mav.command_long_send(1, 1, 22, 0, 0, 0, 0, 0, 0, 0, alt)  # NAV_TAKEOFF


@contextlib.asynccontextmanager
async def _following() -> AsyncIterator[tuple[Any, World, Any]]:
    """A simulated vehicle served alone (GNSS error of millimetres) and a world following it."""
    precise = CopterConfig(seed=3, gnss=GnssParams(sigma_3d_m=0.005))
    async with run_vehicle(speed=SPEED, config=precise) as sim:
        world = await build(_config(sim, SPEED))
        async with world:
            yield sim, world, next(p for p in world.parts if p.name == "follower")


async def test_the_world_builds_the_base_at_home_and_sees_the_vehicle_where_it_reports():
    async with _following() as (sim, world, follower):
        c = sim.copter
        assert world.base.pad_geodetic == (c.origin.lat, c.origin.lon, c.origin.alt)
        await eventually(lambda: world.base.pad_mass_g == MASS_G, 5, "the UAV on the scale")
        assert world.base.contacts_seated  # it booted at home, which is the pad

        peer = Peer(f"tcp:127.0.0.1:{sim.tcp_port}")
        await _take_off(peer, 5.0)
        await eventually(lambda: follower.pose()[2] > SEAT_HEIGHT + 4.5, 10, "up 5 m")
        await eventually(lambda: world.base.pad_mass_g == 0.0, 5, "the scale empty")
        assert not world.base.contacts_seated
        await eventually(lambda: abs(c.dyn.state.velocity[2]) < 0.05, 10, "hovering")
        n, e, up, _roll, _pitch, yaw = follower.pose()
        est = c.estimated_position()
        assert math.hypot(n - est[0], e - est[1]) < 0.05  # 1e-7 degrees is about 1 cm
        assert abs(up - SEAT_HEIGHT - c.dyn.state.altitude) < 0.1
        assert abs(yaw - c.dyn.state.yaw) < 0.05  # ATTITUDE

        async with httpx.AsyncClient() as http:
            r = await http.get(f"http://127.0.0.1:{world.ports['control']}/follower")
        body = r.json()
        assert body["connected"] and not body["landed"] and not body["on_pad"]
        assert body["home"] == list(world.base.pad_geodetic)


async def test_a_sitl_is_seen_where_its_simulator_has_it_not_where_its_gnss_says():
    """A camera sees where the vehicle is. With the autopilot's GNSS 2.2 m off (a bias), the world
    renders from SIMSTATE, the simulator's truth that SITL sends, not from GLOBAL_POSITION_INT's
    estimate. Before, the rendered pad moved with the GNSS error: without RTK corrections the
    external demo's descent gate never settled and it landed 11 cm off the contacts."""
    async with _following() as (sim, _world, follower):
        c = sim.copter
        c.gnss.bias_ne_m = (2.0, -1.0)
        peer = Peer(f"tcp:127.0.0.1:{sim.tcp_port}")
        await _take_off(peer, 5.0)
        await eventually(lambda: follower.pose()[2] > SEAT_HEIGHT + 4.5, 10, "up 5 m")
        await eventually(lambda: abs(c.dyn.state.velocity[2]) < 0.05, 10, "hovering")
        n, e, *_ = follower.pose()
        true_n, true_e, _ = c.dyn.state.position
        est_n, est_e, _ = c.estimated_position()
        assert math.hypot(est_n - true_n, est_e - true_e) > 2.0  # the autopilot's estimate
        assert math.hypot(n - true_n, e - true_e) < 0.05, (n, e, true_n, true_e)
        assert follower.pad_distance() == pytest.approx(math.hypot(true_n, true_e), abs=0.05)


@pytest.mark.slow  # two flights: about 3.5 s
async def test_the_scale_carries_the_vehicle_when_it_lands_on_the_pad_not_beside_it():
    async with _following() as (sim, world, follower):
        c = sim.copter
        peer = Peer(f"tcp:127.0.0.1:{sim.tcp_port}")
        await _take_off(peer, 5.0)
        await eventually(lambda: world.base.pad_mass_g == 0.0, 10, "the scale empty")
        peer.conn.mav.set_mode_send(1, 1, LAND)
        await eventually(lambda: world.base.pad_mass_g == MASS_G, 20, "landed on the pad")
        assert world.base.contacts_seated

        await eventually(lambda: not c.armed, 10, "disarmed after landing")
        await _take_off(peer, 5.0)
        await eventually(lambda: follower.pose()[2] > SEAT_HEIGHT + 4.5, 10, "up again")
        peer.conn.mav.set_position_target_local_ned_send(
            0, 1, 1, 1, 0b110111111000, 3.0, 0.0, -5.0, 0, 0, 0, 0, 0, 0, 0, 0
        )
        await eventually(lambda: follower.pose()[0] > 2.9, 10, "3 m north")
        peer.conn.mav.set_mode_send(1, 1, LAND)
        await eventually(lambda: follower.follower.landed(), 20, "landed beside the pad")
        world.step(0.0)
        assert world.base.pad_mass_g == 0.0 and not world.base.contacts_seated
        status = follower.status()
        assert status["landed"] and not status["on_pad"]
        # where LAND caught it on its way to the 3 m setpoint (sent once the follower saw 2.9 m:
        # the follower's pose, and so the moment, lag the autopilot's): metres off the pad
        assert 2.7 < status["pad_distance_m"] < 3.2


async def test_the_watch_reconnects_when_the_autopilot_restarts():
    port = free_port()
    async with run_vehicle(speed=20.0, seed=1, tcp_port=port) as sim:
        follower = Follower(f"tcp:127.0.0.1:{port}")
        await follower.start()
        try:
            await follower.wait_home(5)
            await eventually(lambda: follower.sample is not None, 5, "a pose")
            await sim.close()  # the autopilot goes away ...
            await eventually(lambda: not follower.link.is_connected, 5, "the drop seen")
            follower.sample = None
            await sim.start()  # ... and comes back on the same port
            await eventually(lambda: follower.sample is not None, 10, "the pose again")
            assert follower.link.is_connected
        finally:
            await follower.stop()


def _msg(kind: str, *fields: float) -> mavlink.MAVLink_message:
    return getattr(mavlink, f"MAVLink_{kind}_message")(*fields)


def test_landed_is_extended_sys_state_when_sent_else_altitude_and_climb_rate():
    f = Follower("tcp:127.0.0.1:5760")  # not started: messages are handed in
    assert f.landed() is None  # nothing known yet
    f.handle(_msg("global_position_int", 0, 411780000, -85960000, 120100, 100, 0, 0, 0, 0))
    assert f.landed() is True  # 0.1 m above home, not moving
    f.handle(_msg("global_position_int", 0, 411780000, -85960000, 122000, 2000, 0, 0, -50, 0))
    assert f.landed() is False  # 2 m up
    f.handle(_msg("global_position_int", 0, 411780000, -85960000, 120200, 200, 0, 0, 60, 0))
    assert f.landed() is False  # low, but still coming down at 0.6 m/s
    f.handle(_msg("extended_sys_state", 0, 2))  # the autopilot says IN_AIR
    f.handle(_msg("global_position_int", 0, 411780000, -85960000, 120100, 100, 0, 0, 0, 0))
    assert f.landed() is False
    f.handle(_msg("extended_sys_state", 0, 1))  # ON_GROUND
    assert f.landed() is True


def test_home_is_the_first_home_position_later_ones_do_not_move_the_pad():
    f = Follower("udpin:127.0.0.1:14550")
    f.handle(_msg("home_position", 411780000, -85960000, 120000, 0, 0, 0, [1, 0, 0, 0], 0, 0, 0))
    f.handle(_msg("home_position", 411780010, -85960000, 120300, 0, 0, 0, [1, 0, 0, 0], 0, 0, 0))
    assert f.home == (41.178, -8.596, 120.0)
    assert f.latest_home == (41.178001, -8.596, 120.3)


@pytest.mark.parametrize(
    ("url", "why"),
    [
        ("tcp:127.0.0.1", "SCHEME:HOST:PORT"),
        ("serial:/dev/ttyS0:57600", "expected one of"),
        ("tcp:127.0.0.1:http", "is not a number"),
        ("udpin::14550", "needs a host"),
        ("tcp:127.0.0.1:70000", "1..65535"),
    ],
)
def test_bad_urls_are_refused_with_the_reason(url, why):
    with pytest.raises(BadUrl, match=why):
        parse_url(url)


def test_world_follow_errors_are_clear_exits(capsys):
    assert world_main(["--follow", "tcp:nowhere"]) == 1
    assert "expected one of tcp, udpin, udp, udpout" in capsys.readouterr().err
    port = free_port()
    assert world_main(["--follow", f"tcp:127.0.0.1:{port}", "--follow-timeout", "0.3"]) == 1
    err = capsys.readouterr().err
    assert f"no HOME_POSITION from tcp:127.0.0.1:{port} within 0.3 s" in err
    assert "never connected" in err


def test_demo_wants_both_autopilot_urls(capsys):
    with pytest.raises(SystemExit) as exc:
        demo_main(["--autopilot", "tcp:127.0.0.1:5760"])
    assert exc.value.code == 2
    assert "--autopilot and --autopilot-watch go together" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        demo_main(["--autopilot", "tcp:127.0.0.1:5760", "--autopilot-watch", "5762"])
    assert "--autopilot-watch: MAVLink URL '5762'" in capsys.readouterr().err


async def test_sim_autopilot_serves_one_vehicle_on_two_tcp_ports_at_its_home():
    args = autopilot_args(
        ["--tcp-port", "0", "--tcp-port2", "0", "--udp-port", "0", "--home", "41.5,-8.25,80"]
    )
    server = autopilot_setup(args)
    await server.start()
    try:
        first = Peer(f"tcp:127.0.0.1:{server.tcp_port}")
        second = Peer(f"tcp:127.0.0.1:{server.tcp_port2}")
        for peer in (first, second):
            peer.conn.mav.command_long_send(1, 1, 512, 0, 242, 0, 0, 0, 0, 0, 0)
            home = await peer.recv("HOME_POSITION")
            assert (home.latitude, home.longitude, home.altitude) == (415000000, -82500000, 80000)
        # one vehicle: a command on the first port is seen on the second
        first.conn.mav.set_mode_send(1, 1, GUIDED)
        await second.recv("HEARTBEAT", custom_mode=GUIDED)
    finally:
        await server.close()


def test_sim_autopilot_flags_its_own_and_sim_vehicles():
    args = autopilot_args(["--tcp-port", "5999", "--tcp-port2", "6001", "--speed", "3"])
    assert (args.tcp_port, args.tcp_port2, args.speed) == (5999, 6001, 3.0)
    with pytest.raises(SystemExit):
        autopilot_args(["--home", "91,0,0"])
    with pytest.raises(SystemExit):
        autopilot_args(["--speed", "0"])


@pytest.mark.slow  # a 2 s reboot and the 2 s silence before streams are asked again: ~5 s
async def test_the_world_follows_an_ardupilot_3_7_through_a_reboot():
    """No SET_MESSAGE_INTERVAL, no EXTENDED_SYS_STATE, quiet streams at boot, and a reboot."""
    habits = profile("ardupilot-3.7", boot_s=0.0)
    config = CopterConfig(seed=3, gnss=GnssParams(sigma_3d_m=0.005), habits=habits)
    async with run_vehicle(speed=SPEED, config=config) as sim:
        world = await build(_config(sim, SPEED))
        async with world:
            part = next(p for p in world.parts if p.name == "follower")
            follower = part.follower
            await eventually(lambda: follower.sample is not None, 5, "a pose (REQUEST_DATA_STREAM)")
            assert follower.landed_state is None  # never sent: landed from altitude and climb
            await eventually(lambda: world.base.pad_mass_g == MASS_G, 5, "the UAV on the scale")

            peer = Peer(f"tcp:127.0.0.1:{sim.tcp_port}")
            peer.conn.mav.command_long_send(1, 1, 246, 0, 1, 0, 0, 0, 0, 0, 0)  # reboot
            await peer.recv("COMMAND_ACK", command=246, result=0)
            rebooted = sim.copter.boots
            await eventually(
                lambda: sim.copter.boots > rebooted and not sim.muted(), 10, "rebooted"
            )
            follower.sample = None  # streams reset at boot: only a new request brings the pose
            await eventually(lambda: follower.sample is not None, 10, "the pose after the reboot")
            await _take_off(peer, 5.0)
            await eventually(lambda: world.base.pad_mass_g == 0.0, 10, "the scale empty")
            assert follower.landed() is False


def test_the_pad_load_is_judged_at_touchdown_and_held_while_landed():
    world = World(WorldConfig.for_tests(control=False))  # not started: the base model alone
    world.base.pad_geodetic = (41.178, -8.596, 120.0)
    follower = Follower("tcp:127.0.0.1:5760")
    part = FollowerPart(follower, SEAT_HEIGHT)
    part.base, part.pad = world.base, GeoOrigin(*world.base.pad_geodetic)

    def report(north_cm: float, rel_alt_m: float, battery: int = 80) -> tuple[float, bool]:
        lat = 411780000 + round(north_cm / 100 / 111_319.49 * 1e7)
        follower.handle(_msg("global_position_int", 0, lat, -85960000, 0, round(rel_alt_m * 1e3), 0, 0, 0, 0))  # fmt: skip
        follower.handle(_msg("sys_status", 0, 0, 0, 0, 16000, 0, battery, 0, 0, 0, 0, 0, 0))
        part.step(0.02)
        return world.base.pad_mass_g, world.base.contacts_seated

    assert report(140, 0.0) == (MASS_G, True)  # before any flight: at home, which is the pad
    assert world.base.charger.uav_soc == 0.8  # the charger takes the battery it reports
    assert report(140, 5.0) == (0.0, False)
    assert report(2, 0.0) == (MASS_G, True)  # touched down 2 cm from the centre
    assert report(30, 0.0) == (MASS_G, True)  # the estimate drifts, the vehicle does not
    assert report(30, 5.0) == (0.0, False)
    assert report(30, 0.0) == (MASS_G, False)  # on the pad, off the contacts
    assert world.base.charger.uav_soc is None
    report(30, 5.0)
    assert report(100, 0.0) == (0.0, False)  # beside the pad
