"""Landing control: LANDING_TARGET fields, the conical acceptance volume, the cautious retries."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest

from asset_agent.precland.config import ControlConfig, RetryConfig
from asset_agent.precland.control import (
    MAV_FRAME_BODY_FRD,
    allowed_pos_error,
    cone_setpoint,
    landing_target,
)
from asset_agent.precland.geometry import rotation_world_from_body
from asset_agent.precland.retry import LandingSequence

C = ControlConfig()


def test_landing_target_angles_follow_ardupilots_line_of_sight():
    att = (0.1, -0.05, 1.2)
    rel = np.array([0.6, -0.4, 3.0])
    lt = landing_target(rel, att, 12.345)
    assert lt.frame == MAV_FRAME_BODY_FRD and lt.position_valid == 1 and lt.distance > 0
    assert lt.time_usec == 12_345_000
    body = rotation_world_from_body(*att).T @ rel
    # ArduPilot AC_PrecLand_Companion: los = (-tan(angle_y), tan(angle_x), 1), normalised
    los = np.array([-math.tan(lt.angle_y), math.tan(lt.angle_x), 1.0])
    assert los / np.linalg.norm(los) == pytest.approx(body / np.linalg.norm(body))
    assert (lt.x, lt.y, lt.z) == pytest.approx(tuple(body)) and lt.distance == pytest.approx(
        np.linalg.norm(rel)
    )


def test_conical_acceptance_function_is_the_papers_equation_3():
    cfg = ControlConfig(min_pos_error=0.05, max_pos_error=0.4)
    assert allowed_pos_error(0.0, cfg) == pytest.approx(0.05)
    assert allowed_pos_error(5.0, cfg) == pytest.approx(0.05 * math.exp(2.0))
    heights = np.linspace(0, 10, 50)
    values = [allowed_pos_error(a, cfg) for a in heights]
    assert all(b > a for a, b in itertools.pairwise(values))  # widens with height


def test_inside_the_cone_descends_to_the_pad_outside_towards_a_minus_allowed():
    a = 4.0  # above touchdown
    h = a + C.touchdown_height
    allowed = allowed_pos_error(a, C)
    inside = cone_setpoint((0.5 * allowed, 0.0, h), 0.0, 0.0, C)
    assert inside.vd == pytest.approx(min(C.kp_z * a, C.max_descent))
    outside = cone_setpoint((2 * allowed, 0.0, h), 0.0, 0.0, C)
    # setpoint altitude a - AllowedPosError(a): the vertical speed shrinks to kp_z * allowed
    assert outside.vd == pytest.approx(C.kp_z * allowed) and outside.vd < inside.vd
    assert outside.vn > 0 and outside.ve == 0  # always centring on the pad


def test_descent_stops_while_heading_error_exceeds_its_limit():
    sp = cone_setpoint((0.0, 0.0, 3.0), math.radians(30), 0.0, C)
    assert sp.vd == 0.0 and sp.yaw_rate > 0
    sp = cone_setpoint((0.0, 0.0, 3.0), math.radians(2), 0.0, C)
    assert sp.vd > 0
    # unknown heading (IR only): descent is not held back
    assert cone_setpoint((0.0, 0.0, 3.0), None, 0.0, C).vd > 0


def test_slow_final_half_metre_and_touchdown():
    t = C.touchdown_height
    assert cone_setpoint((0.0, 0.0, t + 0.4), 0.0, 0.0, C).vd == pytest.approx(C.slow_descent)
    assert cone_setpoint((0.0, 0.0, t + 0.6), 0.0, 0.0, C).vd > C.slow_descent
    assert not cone_setpoint((0.0, 0.0, t + 0.1), 0.0, 0.0, C).land
    assert cone_setpoint((0.0, 0.0, t + 0.01), 0.0, 0.0, C).land
    fast = cone_setpoint((30.0, 40.0, 20.0), 0.0, 0.0, C)
    assert (
        math.hypot(fast.vn, fast.ve) == pytest.approx(C.max_speed_xy) and fast.vd <= C.max_descent
    )


def run(seq, t, seen, rel, vehicle=(0.0, 0.0)):
    return seq.step(t, seen, rel, 0.0, vehicle, 0.0)


def test_cautious_retry_pause_climb_back_retry_then_blind():
    seq = LandingSequence(C, RetryConfig(cautious=True, pause_s=2.0, max_attempts=2))
    assert run(seq, 0.0, True, (0.0, 0.0, 2.5), (5.0, 5.0)).state == "approach"
    # lost at 2 m: pause (hover)
    cmd = run(seq, 1.0, False, (0.0, 0.0, 2.0), (5.0, 5.1))
    assert cmd.state == "pause" and (cmd.setpoint.vn, cmd.setpoint.ve, cmd.setpoint.vd) == (0, 0, 0)
    assert run(seq, 2.9, False, (0.0, 0.0, 2.0)).state == "pause"
    # still lost after pause_s: climb back to where it was last seen (5, 5) at 2.5 m
    cmd = run(seq, 3.0, False, (0.0, 0.0, 2.0), (5.0, 5.1))
    assert cmd.state == "climb" and cmd.attempts == 1 and cmd.setpoint.vd < 0
    assert cmd.setpoint.ve < 0  # back towards east = 5.0
    cmd = run(seq, 4.0, False, (0.0, 0.0, 2.55), (5.0, 5.0))
    assert cmd.state == "pause"  # reached: wait again
    # seen again during the pause: approach resumes
    assert run(seq, 4.5, True, (0.1, 0.0, 2.5), (5.0, 5.0)).state == "approach"
    # lost again: pause, climb (attempt 2), reached, pause, then no attempts left: blind
    run(seq, 5.0, False, (0.0, 0.0, 1.0))
    assert run(seq, 7.1, False, (0.0, 0.0, 1.0)).attempts == 2
    assert run(seq, 8.0, False, (0.0, 0.0, 2.5), (5.0, 5.0)).state == "pause"
    cmd = run(seq, 10.1, False, (0.0, 0.0, 2.5), (5.0, 5.0))
    assert cmd.state == "blind" and cmd.setpoint.vd == pytest.approx(RetryConfig().blind_descent)
    # seen again, then lost with no attempts left: straight to blind, no more pausing
    assert run(seq, 10.2, True, (0.0, 0.0, 2.4), (5.0, 5.0)).state == "approach"
    assert run(seq, 10.3, False, (0.0, 0.0, 2.3), (5.0, 5.0)).state == "blind"
    assert run(seq, 11.0, False, (0.0, 0.0, 0.26)).state == "landed"
    assert run(seq, 12.0, True, (0.0, 0.0, 0.26)).setpoint.land


def test_never_seen_climbs_to_the_default_height():
    seq = LandingSequence(C, RetryConfig(pause_s=1.0, default_height=5.0))
    run(seq, 0.0, False, (0.0, 0.0, 3.0))
    cmd = run(seq, 1.0, False, (0.0, 0.0, 3.0))
    assert cmd.state == "climb" and cmd.setpoint.vd < 0
    assert run(seq, 5.0, False, (0.0, 0.0, 4.5)).state == "climb"
    assert run(seq, 6.0, False, (0.0, 0.0, 4.9)).state == "pause"


def test_default_mode_descends_blind_at_once_when_the_target_is_lost():
    seq = LandingSequence(C, RetryConfig(cautious=False))
    run(seq, 0.0, True, (0.0, 0.0, 3.0))
    cmd = run(seq, 0.1, False, (0.2, 0.0, 2.9))
    assert cmd.state == "blind" and cmd.setpoint.vd > 0 and cmd.setpoint.vn > 0
    assert run(seq, 0.2, True, (0.2, 0.0, 2.8)).state == "approach"


def test_integral_action_removes_a_steady_offset_and_is_bounded():
    cfg = ControlConfig(ki_xy=0.5, max_integral_speed=0.3)
    seq = LandingSequence(cfg, RetryConfig())
    speeds = [
        seq.step(t * 0.1, True, (0.05, 0.0, 5.0), 0.0, (0, 0), 0.0).setpoint.vn for t in range(200)
    ]
    assert speeds[0] == pytest.approx(cfg.kp_xy * 0.05)
    assert speeds[50] > speeds[10] > speeds[0]  # the integral grows with a steady error
    assert speeds[-1] == pytest.approx(cfg.kp_xy * 0.05 + 0.3)  # clamped (anti-windup)
