"""Landing control: LANDING_TARGET fields, the conical acceptance volume, the cautious retries."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest

from asset_agent.precland.config import ControlConfig, RetryConfig, SearchConfig
from asset_agent.precland.control import (
    MAV_FRAME_BODY_FRD,
    allowed_pos_error,
    blind_profile,
    cone_setpoint,
    landing_target,
)
from asset_agent.precland.geometry import rotation_world_from_body
from asset_agent.precland.kalman import FIX_3D, FIX_RTK_FIXED, FIX_RTK_FLOAT
from asset_agent.precland.sequence import LandingSequence

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


def test_inside_the_cone_the_last_centimetres_are_descended_at_a_steady_speed():
    """kp_z x a alone slows to nothing near the seat (the last 10 cm took 3 s, long enough for a
    gust to swing the vehicle out of the cone just above the hand-over): inside the cone the
    descent keeps `final_descent_floor`; outside it still waits."""
    low = C.touchdown_height + 0.05
    near = cone_setpoint((0.0, 0.0, low), 0.0, 0.0, C)
    assert near.vd == pytest.approx(C.final_descent_floor) and near.vd > C.kp_z * 0.05
    assert cone_setpoint((0.1, 0.0, low), 0.0, 0.0, C).vd <= 0.0  # outside: no descent
    former = C.model_copy(update={"final_descent_floor": 0.0})
    assert cone_setpoint((0.0, 0.0, low), 0.0, 0.0, former).vd == pytest.approx(C.kp_z * 0.05)


def test_off_centre_just_above_the_seat_it_backs_off_and_never_hands_over():
    """thesis-field seed 1012: 3 cm above the seat a gust swung the vehicle 4-6 cm off; holding
    height, it sank the last 2 cm on its descent's momentum and the hand-over landed it 7.2 cm
    off. Outside the cone within `back_off_height` of the seat it climbs back, and the hand-over
    to the autopilot's landing waits for the cone."""
    t = C.touchdown_height
    assert C.back_off_height < C.slow_height
    held = cone_setpoint((0.06, 0.0, t + 0.1), 0.0, 0.0, C)
    assert held.vd == 0.0 and not held.land  # higher in the final stretch: wait
    back = cone_setpoint((0.06, 0.0, t + 0.03), 0.0, 0.0, C)
    assert back.vd < 0 and back.vn > 0 and not back.land
    low = cone_setpoint((0.06, 0.0, t + 0.01), 0.0, 0.0, C)
    assert low.vd < 0 and not low.land  # below the hand-over height, off-centre: no landing
    assert cone_setpoint((0.01, 0.0, t + 0.01), 0.0, 0.0, C).land  # centred: land
    seq = LandingSequence(C, RetryConfig(cautious=False))
    run(seq, 0.0, True, (0.0, 0.0, t + 0.05))
    cmd = run(seq, 0.1, True, (0.06, 0.0, t + 0.01))
    assert cmd.state == "approach" and cmd.setpoint.vd < 0 and not cmd.setpoint.land
    assert run(seq, 0.2, True, (0.01, 0.0, t + 0.01)).state == "landed"


def run(seq, t, seen, rel, vehicle=(0.0, 0.0), fix: int | None = FIX_RTK_FIXED):
    return seq.step(t, seen, rel, 0.0, vehicle, 0.0, gnss_fix=fix)


def test_cautious_retry_pause_climb_back_retry_then_blind():
    retry = RetryConfig(cautious=True, pause_s=2.0, max_attempts=2, recentre=False)
    seq = LandingSequence(C, retry)
    assert run(seq, 0.0, True, (0.0, 0.0, 2.5), (5.0, 5.0)).state == "approach"
    # lost at 2 m: pause (hover)
    cmd = run(seq, 1.0, False, (0.0, 0.0, 2.0), (5.0, 5.1))
    assert cmd.state == "pause" and (cmd.setpoint.vn, cmd.setpoint.ve, cmd.setpoint.vd) == (0, 0, 0)
    assert run(seq, 2.9, False, (0.0, 0.0, 2.0)).state == "pause"
    # still lost after pause_s: climb back to where it was last seen (5, 5), above its 2.5 m
    cmd = run(seq, 3.0, False, (0.0, 0.0, 2.0), (5.0, 5.1))
    assert cmd.state == "climb" and cmd.attempts == 1 and cmd.setpoint.vd < 0
    assert cmd.setpoint.ve < 0  # back towards east = 5.0
    assert run(seq, 3.5, False, (0.0, 0.0, 2.55), (5.0, 5.0)).state == "climb"
    cmd = run(seq, 4.0, False, (0.0, 0.0, 2.85), (5.0, 5.0))
    assert cmd.state == "pause"  # reached (2.5 m + margin, within the tolerance): wait again
    # seen again during the pause: approach resumes
    assert run(seq, 4.5, True, (0.1, 0.0, 2.5), (5.0, 5.0)).state == "approach"
    # lost again: pause, climb (attempt 2), reached, pause, then no attempts left: blind
    run(seq, 5.0, False, (0.0, 0.0, 1.0))
    assert run(seq, 7.1, False, (0.0, 0.0, 1.0)).attempts == 2
    assert run(seq, 8.0, False, (0.0, 0.0, 2.85), (5.0, 5.0)).state == "pause"
    cmd = run(seq, 10.1, False, (0.0, 0.0, 2.85), (5.0, 5.0))
    assert cmd.state == "blind"
    assert cmd.setpoint.vd == pytest.approx(blind_profile(2.85 - C.touchdown_height, retry))
    # seen again, then lost with no attempts left: straight to blind, no more pausing
    assert run(seq, 10.2, True, (0.0, 0.0, 2.4), (5.0, 5.0)).state == "approach"
    assert run(seq, 10.3, False, (0.0, 0.0, 2.3), (5.0, 5.0)).state == "blind"
    assert run(seq, 11.0, False, (0.0, 0.0, 0.26)).state == "landed"
    assert run(seq, 12.0, True, (0.0, 0.0, 0.26)).setpoint.land


def test_climb_goes_back_above_the_last_measurement_not_a_held_value():
    seq = LandingSequence(C, RetryConfig(pause_s=1.0, climb_margin_m=0.5, recentre=False))
    seq.step(0.0, True, (0.0, 0.0, 3.1), 0.0, (1.0, 2.0), 0.0)  # measured at 3.1 m over (1, 2)
    # the fusion still holds that value while the vehicle descends: not a sighting
    seq.step(0.5, True, (0.0, 0.0, 2.6), 0.0, (1.5, 2.0), 0.0, fresh=False)
    assert run(seq, 1.0, False, (0.0, 0.0, 2.2), (1.5, 2.0)).state == "pause"
    cmd = run(seq, 2.1, False, (0.0, 0.0, 2.2), (1.5, 2.0))
    assert cmd.state == "climb" and cmd.setpoint.vn < 0  # back north, to 1.0
    # goal 3.1 + 0.5 m: at the height where the target was lost it is not reached yet
    assert run(seq, 3.0, False, (0.0, 0.0, 3.1), (1.0, 2.0)).state == "climb"
    assert run(seq, 3.5, False, (0.0, 0.0, 3.45), (1.0, 2.0)).state == "pause"


def test_blind_after_a_sighting_descends_fast_and_flares_to_the_touchdown_speed():
    r = RetryConfig(
        blind_descent=0.5, blind_fast_descent=1.5, blind_flare_decel=1.5, blind_flare_margin_m=0.1
    )
    assert blind_profile(2.5, r) == pytest.approx(1.5)
    assert blind_profile(0.1, r) == pytest.approx(0.5)  # down to the touchdown speed 10 cm up
    assert blind_profile(0.0, r) == pytest.approx(0.5)
    # v² = v0² + 2 a h, h above the margin
    assert blind_profile(0.5, r) == pytest.approx(math.sqrt(0.5**2 + 2 * 1.5 * 0.4))
    speeds = [blind_profile(h, r) for h in np.linspace(-0.1, 3.0, 32)]
    assert all(0.5 <= v <= 1.5 for v in speeds) and speeds == sorted(speeds)
    # a vehicle tracking the profile with a 3 m/s² limit touches down at about blind_descent
    h, v, dt = 2.75, 0.0, 0.01
    while h > 0:
        want = blind_profile(h, r)
        v += max(-3.0 * dt, min(3.0 * dt, want - v))
        h -= v * dt
    assert v <= 0.5 + 1e-9
    # in the sequence: fast after losing a target it had seen, slow when it never saw one
    seq = LandingSequence(C, RetryConfig(cautious=False, blind_fast_descent=1.5))
    run(seq, 0.0, True, (0.0, 0.0, 3.0))
    cmd = run(seq, 0.1, False, (0.0, 0.0, 2.9))
    assert cmd.state == "blind" and cmd.setpoint.vd == pytest.approx(1.5)
    assert run(seq, 0.2, False, (0.0, 0.0, C.touchdown_height + 0.1)).setpoint.vd < 1.0
    never = LandingSequence(  # the search off: a pad never seen is landed on blind, slowly
        C, RetryConfig(cautious=False, blind_fast_descent=1.5), SearchConfig(enabled=False)
    )
    assert run(never, 0.0, False, (0.0, 0.0, 8.0)).setpoint.vd == pytest.approx(0.5)


def test_a_retry_recentres_over_the_pad_before_descending_again():
    r = RetryConfig(
        pause_s=1.0,
        recentre=True,
        recentre_tolerance_m=0.03,
        recentre_settle_s=1.0,
        recentre_timeout_s=5.0,
    )
    seq = LandingSequence(C, r)
    run(seq, 0.0, True, (0.0, 0.0, 3.1))
    assert run(seq, 0.5, False, (0.0, 0.0, 2.5)).state == "pause"
    assert run(seq, 1.6, False, (0.0, 0.0, 2.5)).state == "climb"
    cmd = run(seq, 2.5, True, (0.2, 0.0, 3.2))  # seen again while climbing back
    assert cmd.state == "recentre" and cmd.setpoint.vd == 0.0 and cmd.setpoint.vn > 0
    assert run(seq, 3.0, True, (0.01, 0.0, 3.2)).state == "recentre"  # over it, not settled
    held = seq.step(3.6, True, (0.01, 0.0, 3.2), 0.0, (0.0, 0.0), 0.0, fresh=False)
    assert held.state == "recentre"  # the fusion's held value is not a fresh sighting
    assert run(seq, 3.7, True, (0.05, 0.0, 3.2)).state == "recentre"  # beyond the tolerance
    cmd = run(seq, 3.8, True, (0.01, 0.0, 3.2))
    assert cmd.state == "approach" and cmd.setpoint.vd > 0
    # never centred: descend anyway once the time allowed is up
    seq = LandingSequence(C, r)
    run(seq, 0.0, True, (0.0, 0.0, 3.1))
    run(seq, 0.5, False, (0.0, 0.0, 2.5))
    run(seq, 1.6, False, (0.0, 0.0, 2.5))
    assert run(seq, 2.5, True, (0.2, 0.0, 3.2)).state == "recentre"
    assert run(seq, 7.4, True, (0.2, 0.0, 3.2)).state == "recentre"
    assert run(seq, 7.5, True, (0.2, 0.0, 3.2)).state == "approach"
    # before any retry (or with re-centring off) a re-acquired target is followed at once
    seq = LandingSequence(C, r)
    assert run(seq, 0.0, False, (0.0, 0.0, 8.0)).state == "acquire"  # never seen yet
    assert run(seq, 0.5, True, (0.3, 0.0, 8.0)).state == "approach"


def test_never_seen_with_the_search_off_climbs_to_the_default_height():
    seq = LandingSequence(
        C, RetryConfig(pause_s=1.0, default_height=5.0), SearchConfig(enabled=False)
    )
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


def test_blind_never_finishes_the_final_stretch_off_centre():
    """Lost in the final 50 cm with the held estimate 20 cm off (a gust pushed the pad out of
    view): steer back at this height; descend once inside the cone, as the approach does —
    while the last sighting is recent (`blind_recentre_s`)."""
    seq = LandingSequence(C, RetryConfig(cautious=False))
    low = C.touchdown_height + 0.1
    run(seq, 0.0, True, (0.0, 0.0, low))
    off = run(seq, 0.1, False, (0.15, 0.12, low))
    assert off.state == "blind" and off.setpoint.vd == 0.0
    assert off.setpoint.vn > 0 and off.setpoint.ve > 0  # towards the estimate
    inside = allowed_pos_error(0.1, C) / 2
    back = run(seq, 0.2, False, (inside, 0.0, low))
    assert back.state == "blind" and back.setpoint.vd > 0
    # higher up the blind descent goes on off-centre, slowed to the cone's surface (the
    # approach's own rule up there)
    high = run(seq, 0.3, False, (0.15, 0.12, 2.0))
    a = 2.0 - C.touchdown_height
    assert high.setpoint.vd == pytest.approx(C.kp_z * allowed_pos_error(a, C))
    # long after the last sighting, on a float or plain fix, the held estimate has drifted with
    # the fix: holding would only add drift, so it descends as it is; on RTK fixed it has not
    late_t = 0.1 + RetryConfig().blind_recentre_s + 0.1
    assert run(seq, late_t, False, (0.15, 0.12, low)).setpoint.vd == 0.0
    for fix in (FIX_RTK_FLOAT, FIX_3D):
        drifting = LandingSequence(C, RetryConfig(cautious=False))
        run(drifting, 0.0, True, (0.0, 0.0, low), fix=fix)
        assert run(drifting, 0.1, False, (0.15, 0.12, low), fix=fix).setpoint.vd == 0.0
        late = run(drifting, late_t, False, (0.15, 0.12, low), fix=fix)
        assert late.state == "blind" and late.setpoint.vd > 0
    # the rule is the approach's switch
    free = LandingSequence(
        C.model_copy(update={"final_inside_cone_only": False}), RetryConfig(cautious=False)
    )
    run(free, 0.0, True, (0.0, 0.0, low))
    assert run(free, 0.1, False, (0.15, 0.12, low)).setpoint.vd > 0


@pytest.mark.parametrize("fix", [FIX_RTK_FLOAT, FIX_3D, None])
def test_without_rtk_fixed_the_last_loss_aborts_instead_of_landing_blind(fix):
    """The marker failing below 3 m on a float or plain fix: the retries used up, the last loss
    climbs to the safe height and holds ("aborted-climb") instead of a blind descent on the
    fix's drift; in the final stretch (within `blind_max_height_unfixed_m`) it goes on blind."""
    retry = RetryConfig(cautious=True, pause_s=1.0, max_attempts=1, recentre=False)
    seq = LandingSequence(C, retry)
    assert run(seq, 0.0, True, (0.0, 0.0, 3.2), (0.0, 0.0), fix).state == "approach"
    assert run(seq, 1.0, False, (0.0, 0.0, 3.0), (0.0, 0.0), fix).state == "pause"
    assert run(seq, 2.0, False, (0.0, 0.0, 3.0), (0.0, 0.0), fix).state == "climb"
    assert run(seq, 4.0, False, (0.0, 0.0, 3.7), (0.0, 0.0), fix).state == "pause"
    cmd = run(seq, 5.1, False, (0.0, 0.0, 3.7), (0.0, 0.0), fix)  # no retry left
    assert cmd.state == "abort" and seq.path == "aborted-climb" and cmd.setpoint.vd < 0
    assert seq.abort_reason == "pad lost, no RTK fix" and not seq.holding_safe
    # seen again on the way up: the landing stays abandoned, for the operator to decide
    assert run(seq, 6.0, True, (0.0, 0.0, 5.0), (0.0, 0.0), fix).state == "abort"
    held = run(seq, 30.0, False, (0.0, 0.0, SearchConfig().abort_height_m), (0.0, 0.0), fix)
    assert held.setpoint.vd == 0.0 and seq.holding_safe
    # the same loss on RTK fixed descends blind, as before
    rtk = LandingSequence(C, retry)
    for t, seen, h in ((0.0, True, 3.2), (1.0, False, 3.0), (2.0, False, 3.0), (4.0, False, 3.7)):
        run(rtk, t, seen, (0.0, 0.0, h))
    assert run(rtk, 5.1, False, (0.0, 0.0, 3.7)).state == "blind"
    # without retries (the default mode): lost at 3 m aborts, lost in the final stretch is blind
    plain = LandingSequence(C, RetryConfig(cautious=False))
    run(plain, 0.0, True, (0.0, 0.0, 3.0), (0.0, 0.0), fix)
    assert run(plain, 0.1, False, (0.0, 0.0, 2.9), (0.0, 0.0), fix).state == "abort"
    low = LandingSequence(C, RetryConfig(cautious=False))
    run(low, 0.0, True, (0.0, 0.0, C.touchdown_height + 0.45), (0.0, 0.0), fix)
    lost = run(low, 0.1, False, (0.0, 0.0, C.touchdown_height + 0.45), (0.0, 0.0), fix)
    assert lost.state == "blind" and lost.setpoint.vd > 0
    # last measured above the final stretch, noticed inside it (the fusion held the pad while the
    # vehicle went on down): the blind descent began up there, so it aborts
    late = LandingSequence(C, RetryConfig(cautious=False))
    run(late, 0.0, True, (0.0, 0.0, C.touchdown_height + 0.9), (0.0, 0.0), fix)
    assert run(late, 1.0, False, (0.0, 0.0, C.touchdown_height + 0.4), (0.0, 0.0), fix).state == (
        "abort"
    )
    # the thesis's rule, blind from any height on any fix, is one setting away
    thesis = LandingSequence(C, RetryConfig(cautious=False, blind_max_height_unfixed_m=None))
    run(thesis, 0.0, True, (0.0, 0.0, 3.0), (0.0, 0.0), fix)
    assert run(thesis, 0.1, False, (0.0, 0.0, 2.9), (0.0, 0.0), fix).state == "blind"


def test_integral_action_removes_a_steady_offset_and_is_bounded():
    cfg = ControlConfig(ki_xy=0.5, max_integral_speed=0.3)
    seq = LandingSequence(cfg, RetryConfig())
    speeds = [
        seq.step(t * 0.1, True, (0.05, 0.0, 5.0), 0.0, (0, 0), 0.0).setpoint.vn for t in range(200)
    ]
    assert speeds[0] == pytest.approx(cfg.kp_xy * 0.05)
    assert speeds[50] > speeds[10] > speeds[0]  # the integral grows with a steady error
    assert speeds[-1] == pytest.approx(cfg.kp_xy * 0.05 + 0.3)  # clamped (anti-windup)


def test_blind_descent_held_off_the_pad_by_the_wind_waits_then_aborts():
    """fused-wind12, seed 1006: lost 1.3 m up while a gust carried the vehicle off, the blind
    descent went down regardless and landed 3.2 m off the pad. Now, within `blind_wait_height_m`
    of touchdown, it keeps to the cone on its RTK fixed estimate (slowing to the cone's surface,
    never descending the final stretch off it) and, held outside the cone `blind_hold_max_s` in
    all, climbs and holds: not landed beside the pad."""
    retry = RetryConfig(cautious=False, blind_hold_max_s=3.0)
    seq = LandingSequence(C, retry)
    run(seq, 0.0, True, (0.0, 0.0, 1.6))
    t, h, rel = 0.0, 1.6, (0.45, -0.12, 1.6)
    for _ in range(20):  # 2 s blown 0.45-1.2 m off: it does not come down to the seat
        t += 0.1
        cmd = run(seq, t, False, rel)
        assert cmd.state == "blind" and cmd.setpoint.vd <= C.kp_z * allowed_pos_error(h, C)
        assert cmd.setpoint.vn > 0 and cmd.setpoint.ve < 0  # steering back to the estimate
        h -= cmd.setpoint.vd * 0.1
        rel = (min(rel[0] + 0.04, 1.2), rel[1], h)
    assert h > 1.5
    # back inside the cone: the blind descent goes on at its own speed
    back = run(seq, t + 0.1, False, (0.0, 0.0, h))
    assert back.state == "blind" and back.setpoint.vd > 0.5
    # blown off again: 3 s outside the cone in all, and it gives the landing up
    t += 0.1
    while (cmd := run(seq, t, False, (0.8, 0.0, h))).state == "blind":
        t += 0.1
        assert t < 10.0
    assert cmd.state == "abort" and seq.path == "aborted-climb" and cmd.setpoint.vd < 0
    assert seq.abort_reason == "held off the pad by the wind"  # the landing_aborted event's
    assert t == pytest.approx(0.2 + 3.0 + 0.1, abs=0.25)  # 2 s, then 1 s more, outside
    # higher than `blind_wait_height_m` it descends off the cone: up there the wind is stronger,
    # and waiting let 12 m/s carry the vehicle 11 m off (seed 1010) where descending found the pad
    high = LandingSequence(C, retry)
    run(high, 0.0, True, (0.0, 0.0, 8.0))
    a = 7.0 - C.touchdown_height
    assert a > retry.blind_wait_height_m
    cmd = run(high, 0.1, False, (1.5, 1.0, 7.0))
    assert cmd.state == "blind" and cmd.setpoint.vd == pytest.approx(blind_profile(a, retry))
    # in the final stretch it never touches down outside the cone
    low = C.touchdown_height + C.land_margin / 2
    final = LandingSequence(C, retry)
    run(final, 0.0, True, (0.0, 0.0, 0.5))
    assert run(final, 0.1, False, (0.3, 0.0, low)).state == "blind"
    assert run(final, 0.2, False, (0.0, 0.0, low)).state == "landed"


def test_a_climb_back_the_wind_keeps_from_its_goal_ends_after_its_timeout():
    """12 m/s, the autopilot path, seed 1019: lost at 8.7 m and blown 20-50 m off the point it was
    climbing back to, the retry's climb never "reached" it and went on climbing to 22 m. Now a
    climb that has not got there in `climb_timeout_s` pauses where it is, and the retries go on."""
    retry = RetryConfig(cautious=True, pause_s=1.0, max_attempts=2, recentre=False)
    seq = LandingSequence(C, retry)
    run(seq, 0.0, True, (0.0, 0.0, 8.7))
    run(seq, 0.1, False, (0.0, 0.0, 8.7))
    assert run(seq, 1.2, False, (0.0, 0.0, 8.7)).state == "climb"
    t = 1.2
    while t + 0.5 < 1.2 + retry.climb_timeout_s:  # climbing on, blown 39 m off its goal
        t += 0.5
        assert run(seq, t, False, (0.0, 0.0, 9.5), (25.0, -30.0)).state == "climb"
    cmd = run(seq, 1.2 + retry.climb_timeout_s + 0.1, False, (0.0, 0.0, 9.5), (25.0, -30.0))
    assert cmd.state == "pause" and seq.attempts == 1
