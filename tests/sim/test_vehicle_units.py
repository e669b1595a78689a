"""Pure parts of the simulated autopilot: dynamics, GNSS/RTK model, precision landing, mission upload."""

from __future__ import annotations

import itertools
import math

import pytest
from pymavlink.dialects.v20 import ardupilotmega as mavlink

from sim.vehicle import mission as ms
from sim.vehicle.dynamics import Dynamics, DynamicsParams, Phase
from sim.vehicle.geo import GeoOrigin
from sim.vehicle.gnss import FIX_3D, FIX_RTK_FIXED, FIX_RTK_FLOAT, GnssModel
from sim.vehicle.precland import MAV_FRAME_BODY_FRD, PrecisionLanding, TargetReading


def fly(dyn: Dynamics, seconds: float, dt: float = 0.05, wind=(0.0, 0.0)) -> list:
    states = []
    for _ in range(round(seconds / dt)):
        states.append(dyn.step(dt, wind))
    return states


def test_position_target_reached_and_held_within_limits() -> None:
    p = DynamicsParams(max_speed_h=8.0, max_accel=2.0)
    dyn = Dynamics(p)
    dyn.motors_on = True
    dyn.set_position_target((50.0, -20.0, -10.0))
    states = fly(dyn, 40)
    n, e, d = dyn.state.position
    assert math.dist((n, e, d), (50.0, -20.0, -10.0)) < 0.05
    # the limits shape the velocity the controller asks for; the vehicle's lean follows with a
    # time constant, so what it flies overshoots that by a few per cent
    assert max(math.hypot(s.velocity[0], s.velocity[1]) for s in states) <= 8.0 * 1.03
    assert min(s.velocity[2] for s in states) >= -p.max_speed_up - 1e-9
    accel = max(math.dist(a.velocity, b.velocity) / 0.05 for a, b in itertools.pairwise(states))
    assert accel <= p.max_accel * math.sqrt(3) * 1.15
    assert not dyn.state.landed


def test_velocity_target_wind_and_landing() -> None:
    dyn = Dynamics()
    dyn.motors_on = True
    dyn.set_velocity_target((0.0, 0.0, -2.0))
    fly(dyn, 5)
    assert dyn.state.altitude > 5 and not dyn.state.landed
    dyn.hold()
    east0 = dyn.state.position[1]
    fly(dyn, 2, wind=(0.0, 10.0))
    assert dyn.state.position[1] > east0  # a sudden wind pushes the vehicle off
    fly(dyn, 20, wind=(0.0, 10.0))
    assert abs(dyn.state.position[1] - east0) < 0.05  # a steady wind is learnt and rejected
    dyn.set_position_target((dyn.state.position[0], dyn.state.position[1], 1.0), speed_down=1.0)
    fly(dyn, 20)
    assert dyn.state.landed and dyn.state.position[2] == 0.0 and dyn.state.velocity == (0, 0, 0)


def test_battery_drains_faster_in_flight_than_on_the_ground() -> None:
    ground = Dynamics()
    ground.motors_on = True
    fly(ground, 60)
    air = Dynamics()
    air.motors_on = True
    air.set_velocity_target((8.0, 0.0, -0.5))
    fly(air, 60)
    assert air.state.phase in (Phase.CRUISE, Phase.CLIMB)
    assert 100 - air.state.battery_pct > 5 * (100 - ground.state.battery_pct)
    assert ground.state.voltage > air.state.voltage


def test_geo_round_trip() -> None:
    o = GeoOrigin(41.178, -8.596, 120.0)
    lat, lon, alt = o.to_geodetic(100.0, -50.0, -20.0)
    assert alt == 140.0
    n, e, d = o.to_ned(lat, lon, alt)
    assert (round(n, 6), round(e, 6), round(d, 6)) == (100.0, -50.0, -20.0)


def test_gnss_rtk_float_then_fixed_then_back_to_3d() -> None:
    g = GnssModel(seed=1)
    assert g.fix_type(0.0) == FIX_3D
    assert g.reading(0.0).h_acc_m > 0.5
    for i in range(10):
        g.correction(i * 0.5, valid=True)
        if i == 0:
            assert g.fix_type(0.0) == FIX_RTK_FLOAT
    assert g.fix_type(4.5) == FIX_RTK_FIXED
    r = g.step(0.1, 4.5)
    assert max(abs(x) for x in r.error_ned[:2]) < 0.1 and r.satellites > 14
    assert g.fix_type(4.5 + 3.1) == FIX_3D  # corrections stopped more than 3 s ago


def test_gnss_bad_frames_do_not_help() -> None:
    g = GnssModel(seed=1)
    for i in range(10):
        g.correction(i * 0.1, valid=False)
    assert g.fix_type(1.0) == FIX_3D and g.bad_frames == 10


def test_gnss_error_is_a_bounded_random_walk() -> None:
    g = GnssModel(seed=3)
    errs = [g.step(0.1, 0.0).error_ned[0] for _ in range(20000)]
    assert 0.3 < max(abs(e) for e in errs) < 6.0
    assert max(abs(a - b) for a, b in itertools.pairwise(errs)) < 0.05


def test_precland_frames_angles_and_timeouts() -> None:
    pl = PrecisionLanding()
    level = (0.0, 0.0, 0.0)
    assert "Frame not supported" in (pl.handle(TargetReading(1), 0.0, (0, 0), 10, level) or "")
    assert pl.handle(TargetReading(MAV_FRAME_BODY_FRD, position_valid=True), 0.0, (0, 0), 10, level)
    # 45 degrees right of nadir at 10 m, vehicle facing north: target 10 m east
    assert (
        pl.handle(TargetReading(MAV_FRAME_BODY_FRD, angle_x=math.pi / 4), 0.0, (0, 0), 10, level)
        is None
    )
    n, e = pl.target_ne(0.5) or (None, None)
    assert abs(n) < 1e-9 and abs(e - 10.0) < 1e-9
    # facing east, a position 3 m forward at distance 5: direction only, scaled by height
    pos = TargetReading(12, distance=5.0, x=3.0, y=0.0, z=4.0, position_valid=True)
    assert pl.handle(pos, 1.0, (0, 0), 8, (0.0, 0.0, math.pi / 2)) is None
    n, e = pl.target_ne(1.5) or (None, None)
    assert abs(n) < 1e-9 and abs(e - 6.0) < 1e-9
    assert pl.fresh(1.9) and not pl.fresh(2.1)
    # LOCAL_FRD ignores roll and pitch; BODY_FRD does not
    banked = (math.radians(20), 0.0, 0.0)
    local = PrecisionLanding()
    local.handle(TargetReading(20), 0.0, (0, 0), 10, banked)
    assert local.target_ne(0.0) == (0.0, 0.0)
    body = PrecisionLanding()
    body.handle(TargetReading(MAV_FRAME_BODY_FRD), 0.0, (0, 0), 10, banked)
    assert body.target_ne(0.0)[1] == pytest.approx(-10 * math.tan(math.radians(20)))
    assert pl.target_ne(2.9) is not None and pl.target_ne(3.1) is None and pl.lost(3.1)


def test_mission_item_validation() -> None:
    wp = ms.Item(1, 6, ms.NAV_WAYPOINT, x=411780000, y=-85960000, z=20)
    assert ms.validate(wp) == ms.ACCEPTED
    assert ms.validate(ms.Item(1, 6, 84)) == ms.UNSUPPORTED  # NAV_VTOL_TAKEOFF
    assert ms.validate(ms.Item(1, 2, 206, param1=25)) == ms.ACCEPTED  # camera trigger: stored
    assert ms.validate(ms.Item(1, 2, ms.DO_JUMP, param1=0)) == ms.INVALID_PARAM1
    assert ms.validate(ms.Item(1, 2, ms.NAV_DELAY, param1=5)) == ms.ACCEPTED
    assert ms.validate(ms.Item(1, 1, ms.NAV_WAYPOINT)) == ms.UNSUPPORTED_FRAME
    assert ms.validate(ms.Item(1, 6, ms.NAV_WAYPOINT, x=int(91e7))) == ms.INVALID_PARAM5_X
    assert ms.validate(ms.Item(1, 6, ms.NAV_WAYPOINT, y=int(-181e7))) == ms.INVALID_PARAM6_Y
    assert ms.validate(ms.Item(1, 6, ms.NAV_WAYPOINT, z=20000)) == ms.INVALID_PARAM7
    assert ms.validate(ms.Item(1, 6, ms.NAV_LOITER_TIME, param1=-1)) == ms.INVALID_PARAM1
    assert ms.validate(ms.Item(1, 2, ms.DO_CHANGE_SPEED, param2=0)) == ms.INVALID_PARAM2
    assert ms.validate(ms.Item(1, 2, ms.NAV_RETURN_TO_LAUNCH)) == ms.ACCEPTED
    assert ms.validate(ms.Item(1, 3, ms.NAV_TAKEOFF, param4=math.nan, z=10)) == ms.ACCEPTED


def test_upload_state_machine_requests_resends_and_cancels() -> None:
    up = ms.Upload(3, now=0.0)
    assert up.start() == ("request", 0)
    assert up.on_item(ms.Item(0, 0, 16), 0.1) == ("request", 1)
    assert up.on_item(ms.Item(0, 0, 16), 0.2) is None  # duplicate ignored
    assert up.on_item(ms.Item(2, 3, 16), 0.2) == ("request", 1)  # out of order
    assert up.update(0.5) is None
    assert up.update(1.3) == ("request", 1)  # re-request after 1 s
    assert up.update(9.0) == ("ack", ms.OPERATION_CANCELLED)  # 8 s of silence
    assert up.done


def test_upload_rejects_bad_item_and_too_many() -> None:
    up = ms.Upload(2, now=0.0)
    up.start()
    up.on_item(ms.Item(0, 0, 16), 0.0)
    assert up.on_item(ms.Item(1, 6, 16, x=int(95e7)), 0.0) == ("ack", ms.INVALID_PARAM5_X)
    assert ms.Upload(ms.MAX_ITEMS + 1, 0.0).start() == ("ack", ms.NO_SPACE)
    ok = ms.Upload(2, 0.0)
    ok.start()
    ok.on_item(ms.Item(0, 0, 16), 0.0)
    assert ok.on_item(ms.Item(1, 3, 22, z=10), 0.0) == ("ack", ms.ACCEPTED)
    assert ms.starts_with_takeoff([ms.Item(0, 0, 16), *ok.items[1:]])


def test_mission_flight_steps_over_passive_items_and_jumps() -> None:
    from sim.vehicle.copter import Copter, CopterConfig
    from sim.vehicle.standalone import OpenPad

    c = Copter(OpenPad(), CopterConfig(seed=2))
    lat, lon = round(41.1780 * 1e7), round(-8.5960 * 1e7)
    c.items = [
        c.home_item(),
        ms.Item(1, 3, ms.NAV_TAKEOFF, z=5),
        ms.Item(2, 2, 206, param1=20),  # camera trigger distance: nothing to fly
        ms.Item(3, 3, ms.NAV_WAYPOINT, x=lat + 200, y=lon, z=5),  # 2.2 m north
        ms.Item(4, 2, ms.DO_JUMP, param1=3, param2=2),  # fly item 3 twice more
        ms.Item(5, 3, ms.NAV_LAND),
    ]
    assert c.set_mode(4) and c.arm() == 0 and c.set_mode(3)
    reached = []
    for _ in range(4000):
        c.tick(0.05, 0.0)
        reached += [m.seq for _, m in c.outbox if m.get_type() == "MISSION_ITEM_REACHED"]
        c.outbox.clear()
        if not c.armed:
            break
    assert reached == [1, 3, 3, 3, 5]
    assert not c.armed and c.dyn.state.landed


def test_gnss_bias_moves_the_landing_point() -> None:
    from sim.vehicle.copter import Copter, CopterConfig
    from sim.vehicle.standalone import OpenPad

    pad = OpenPad()
    c = Copter(pad, CopterConfig(seed=4))
    c.set_mode(4)
    c.arm()
    c.guidance.takeoff(5)
    wall = 0.0
    for i in range(6000):
        wall += 0.05
        if i % 4 == 0:
            c.gnss.correction(wall, True)  # RTK: the bias dominates the error
        if i == 100:
            c.gnss.bias_ne_m = (2.0, 0.0)  # multipath: the vehicle believes it is 2 m north
            c.set_mode(6)
        c.tick(0.05, wall)
        c.outbox.clear()
        if i > 100 and not c.armed:
            break
    n, e, _ = c.dyn.state.position
    assert abs(n + 2.0) < 0.1 and abs(e) < 0.1  # landed 2 m south of the pad, off it
    assert pad.mass_g == 0 and not pad.contacts_seated


def test_leaving_auto_stops_the_mission_as_ardupilot_reports_it() -> None:
    # ModeAuto::exit stops AP_Mission (MISSION_STOPPED), which GCS_MAVLINK::mission_state reports
    # NOT_STARTED; Copter says PAUSED only for a DO_PAUSE_CONTINUE pause in AUTO. AUTO resumes it
    from sim.vehicle.constants import MISSION_ACTIVE, MISSION_COMPLETE, MISSION_NOT_STARTED
    from sim.vehicle.copter import Copter, CopterConfig
    from sim.vehicle.standalone import OpenPad

    c = Copter(OpenPad(), CopterConfig(seed=2))
    lat, lon = round(41.1780 * 1e7), round(-8.5960 * 1e7)
    c.items = [
        c.home_item(),
        ms.Item(1, 3, ms.NAV_TAKEOFF, z=5),
        ms.Item(2, 3, ms.NAV_WAYPOINT, x=lat + 900, y=lon, z=5),  # 10 m north
        ms.Item(3, 2, ms.NAV_RETURN_TO_LAUNCH),
    ]
    assert c.guidance.reported_mission_state() == MISSION_NOT_STARTED
    assert c.set_mode(4) and c.arm() == 0 and c.set_mode(3)
    while c.mission_current < 2:
        c.tick(0.05, 0.0)
    assert c.guidance.reported_mission_state() == MISSION_ACTIVE
    assert c.set_mode(5)  # LOITER
    assert c.guidance.reported_mission_state() == MISSION_NOT_STARTED
    assert c.set_mode(3)
    assert c.mission_current == 2 and c.guidance.reported_mission_state() == MISSION_ACTIVE
    for _ in range(4000):
        c.tick(0.05, 0.0)
        if not c.armed:
            break
    assert c.guidance.reported_mission_state() == MISSION_COMPLETE


def test_land_disarms_a_second_after_touchdown_and_guided_lifts_off_before_it() -> None:
    """ArduPilot's land detector: on the ground LAND_DETECTOR_TRIGGER_SEC (1 s) before
    land_complete; LAND disarms then and EXTENDED_SYS_STATE says ON_GROUND. In that second GUIDED
    still flies: a climb sent there lifts the vehicle off again (after it, GUIDED idles)."""
    from sim.vehicle.constants import LANDING, ON_GROUND
    from sim.vehicle.copter import Copter, CopterConfig
    from sim.vehicle.standalone import OpenPad

    velocity_only = 0b0000_1101_1100_0111
    climb = mavlink.MAVLink_set_position_target_local_ned_message(
        0, 1, 1, 1, velocity_only, 0, 0, 0, 0, 0, -1.0, 0, 0, 0, 0, 0
    )
    for climb_at in (None, 0.5):
        c = Copter(OpenPad(), CopterConfig(seed=2))
        assert c.set_mode(4) and c.arm() == 0 and c.guidance.takeoff(3) == 0
        while c.dyn.state.altitude < 2.9 and c.t < 30.0:
            c.tick(0.05, 0.0)
        assert c.set_mode(9)  # LAND
        while not c.dyn.state.landed and c.t < 60.0:
            c.tick(0.05, 0.0)
        assert c.dyn.state.landed and c.armed
        down = c.t
        while c.armed and c.t < down + 3.0 and c.dyn.state.landed:
            assert c.guidance.landed_state() == LANDING, c.t - down
            if climb_at is not None and c.t >= down + climb_at:
                assert c.set_mode(4)  # GUIDED, climbing at 1 m/s
                c.handle(climb, None, 0.0)
            c.tick(0.05, 0.0)
        if climb_at is None:  # disarmed by LAND one second after touchdown
            assert not c.armed and 0.95 <= c.t - down <= 1.1, c.t - down
            assert c.guidance.landed_state() == ON_GROUND
        else:  # lifted off again before the detector had seen the touchdown
            assert c.armed and not c.dyn.state.landed and c.t - down < 1.0


def test_armed_on_the_ground_without_a_takeoff_disarms_after_disarm_delay() -> None:
    """ArduPilot's auto-disarm: armed in GUIDED and left on the ground (no takeoff), the vehicle
    disarms itself DISARM_DELAY (10 s) after arming; a takeoff sent before then keeps it armed;
    DISARM_DELAY 0 never disarms; a manual disarm and re-arm starts the delay again."""
    from sim.vehicle.copter import Copter, CopterConfig
    from sim.vehicle.standalone import OpenPad

    def armed_for(c: Copter, limit: float, takeoff_at: float | None = None) -> float:
        """Simulated seconds it stays armed, ticked at 1x (the delay is counted in wall time)."""
        start = c.t
        while c.armed and c.t < start + limit:
            if takeoff_at is not None and c.t >= start + takeoff_at and c.dyn.state.landed:
                assert c.guidance.takeoff(3) == 0
                takeoff_at = None
            c.tick(0.05, c.t + 0.05)
        return c.t - start

    c = Copter(OpenPad(), CopterConfig(seed=2))
    assert c.param("DISARM_DELAY") == 10
    assert c.set_mode(4) and c.arm() == 0  # GUIDED
    assert 9.95 <= armed_for(c, 30.0) <= 10.1 and not c.armed

    assert c.arm() == 0  # armed again, then a takeoff 8 s later: still armed 30 s on
    assert armed_for(c, 30.0, takeoff_at=8.0) >= 30.0 and c.armed and c.flying

    c = Copter(OpenPad(), CopterConfig(seed=2))
    assert c.set_mode(4) and c.arm() == 0
    armed_for(c, 6.0)
    assert c.disarm() == 0 and c.arm() == 0  # the timer starts again at arming
    assert 9.95 <= armed_for(c, 30.0) <= 10.1

    c = Copter(OpenPad(), CopterConfig(seed=2))
    assert c.set_param("DISARM_DELAY", 0) and c.set_mode(4) and c.arm() == 0
    assert armed_for(c, 30.0) >= 30.0 and c.armed

    c = Copter(OpenPad(), CopterConfig(seed=2))  # 30 simulated seconds in 3 wall seconds (10x)
    assert c.set_mode(4) and c.arm() == 0
    for _ in range(600):
        c.tick(0.05, c.t / 10)
    assert c.armed
