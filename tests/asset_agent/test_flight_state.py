"""Each inference of asset_agent/autopilot/flight_state.py: landed state and mission completion
for autopilots that send no EXTENDED_SYS_STATE and no MISSION_CURRENT.mission_state."""

from __future__ import annotations

from dataclasses import replace

import pytest

from asset_agent.autopilot.flight_state import MissionWatch, infer_landed_state
from asset_agent.autopilot.state import UavState
from asset_agent.events import EventTracker

HOME = (41.178, -8.596)
GROUND = UavState(
    link_up=True, armed=True, system_status=4, mode="GUIDED", alt_rel=0.0, vd=0.0,
    lat=HOME[0], lon=HOME[1], home_lat=HOME[0], home_lon=HOME[1],
)  # fmt: skip
AWAY = {"lat": HOME[0] + 0.0005, "lon": HOME[1]}  # 56 m north of home


def _s(**kw: object) -> UavState:
    return replace(GROUND, **kw)  # type: ignore[arg-type]


@pytest.mark.parametrize("prev", ["UNDEFINED", "ON_GROUND", "TAKEOFF", "IN_AIR", "LANDING"])
def test_disarmed_or_standby_is_on_the_ground(prev: str):
    assert infer_landed_state(prev, _s(armed=False, alt_rel=12.0)) == "ON_GROUND"
    assert infer_landed_state(prev, _s(system_status=3, alt_rel=12.0)) == "ON_GROUND"


def test_armed_on_the_ground_stays_on_the_ground():
    assert infer_landed_state("ON_GROUND", _s(alt_rel=0.2, vd=-0.1)) == "ON_GROUND"
    assert infer_landed_state("UNDEFINED", _s(alt_rel=None, vd=None)) == "ON_GROUND"


def test_climbing_or_above_a_metre_is_taking_off():
    assert infer_landed_state("ON_GROUND", _s(alt_rel=0.3, vd=-0.8)) == "TAKEOFF"
    assert infer_landed_state("ON_GROUND", _s(alt_rel=1.5, vd=0.0)) == "TAKEOFF"
    assert infer_landed_state("TAKEOFF", _s(alt_rel=8.0, vd=-2.0)) == "TAKEOFF"


def test_the_climb_ending_above_a_metre_is_in_the_air():
    assert infer_landed_state("TAKEOFF", _s(alt_rel=20.0, vd=-0.1)) == "IN_AIR"
    assert infer_landed_state("IN_AIR", _s(mode="AUTO", alt_rel=20.0, vd=1.0)) == "IN_AIR"


def test_descending_in_a_landing_mode_is_landing_and_stays_so():
    for mode in ("LAND", "RTL"):
        assert infer_landed_state("IN_AIR", _s(mode=mode, alt_rel=10.0, vd=0.8)) == "LANDING"
    assert infer_landed_state("IN_AIR", _s(mode="RTL", alt_rel=15.0, vd=0.0)) == "IN_AIR"
    assert infer_landed_state("LANDING", _s(mode="LAND", alt_rel=5.0, vd=0.0)) == "LANDING"
    assert infer_landed_state("LANDING", _s(mode="LOITER", alt_rel=5.0, vd=0.0)) == "IN_AIR"


def test_an_rtl_descent_lands_only_near_home():
    # RTL's final descent over home is landing; descending on the way home (a cone, terrain) is not
    assert infer_landed_state("IN_AIR", _s(mode="RTL", alt_rel=9.0, vd=0.8, **AWAY)) == "IN_AIR"
    near = {"lat": HOME[0] + 0.00003, "lon": HOME[1]}  # 3.3 m
    assert infer_landed_state("IN_AIR", _s(mode="RTL", alt_rel=9.0, vd=0.8, **near)) == "LANDING"
    unknown_home = _s(mode="RTL", alt_rel=9.0, vd=0.8, home_lat=None, home_lon=None)
    assert infer_landed_state("IN_AIR", unknown_home) == "IN_AIR"
    # LAND mode lands where it is
    assert infer_landed_state("IN_AIR", _s(mode="LAND", alt_rel=9.0, vd=0.8, **AWAY)) == "LANDING"


def test_auto_flying_a_final_rtl_or_land_item_lands_like_the_mode():
    # ArduPilot 3.x flies a mission's last RTL item in AUTO: its final descent over home is landing
    rtl, land, wp = 20, 21, 16
    over_home = _s(mode="AUTO", alt_rel=9.0, vd=0.8)
    away = _s(mode="AUTO", alt_rel=9.0, vd=0.8, **AWAY)
    assert infer_landed_state("IN_AIR", over_home, command=rtl) == "LANDING"
    assert infer_landed_state("IN_AIR", away, command=rtl) == "IN_AIR"
    assert infer_landed_state("IN_AIR", away, command=land) == "LANDING"
    # a waypoint lower than the last one, or an unknown item, is no landing
    assert infer_landed_state("IN_AIR", over_home, command=wp) == "IN_AIR"
    assert infer_landed_state("IN_AIR", over_home) == "IN_AIR"
    # an RTL item climbing to RTL_ALT is no landing either
    climbing = _s(mode="AUTO", alt_rel=9.0, vd=-1.5)
    assert infer_landed_state("IN_AIR", climbing, command=rtl) == "IN_AIR"


def test_still_below_a_metre_after_flying_is_touched_down():
    for prev in ("IN_AIR", "LANDING", "TAKEOFF"):
        assert infer_landed_state(prev, _s(mode="LAND", alt_rel=0.1, vd=0.05)) == "ON_GROUND"
    assert infer_landed_state("LANDING", _s(mode="LAND", alt_rel=0.5, vd=0.5)) == "LANDING"
    # ArduPilot's precision landing slows to 0.1 m/s in its final metres: still landing, so the
    # agent keeps feeding it LANDING_TARGET (a 3.7 run stopped at 0.98 m when this read landed)
    assert infer_landed_state("LANDING", _s(mode="RTL", alt_rel=0.8, vd=0.1)) == "LANDING"
    assert infer_landed_state("IN_AIR", _s(mode="RTL", alt_rel=0.8, vd=0.1)) == "ON_GROUND"


def test_unknown_altitude_keeps_the_last_inference():
    assert infer_landed_state("IN_AIR", _s(alt_rel=None, vd=None)) == "IN_AIR"


AUTO_LAST = _s(mode="AUTO", mission_current=4, mission_total=5, mission_state="ACTIVE", alt_rel=20)


def test_reaching_the_last_item_finishes_the_mission():
    w = MissionWatch()
    w.uploaded(5)
    assert w.on_reached(AUTO_LAST, 4).mission_state == "ACTIVE"  # seq 4: item 3
    assert w.on_reached(AUTO_LAST, 5).mission_state == "COMPLETE"


def test_disarming_in_auto_on_the_last_item_finishes_the_mission():
    w = MissionWatch()
    w.uploaded(5)
    earlier = replace(AUTO_LAST, mission_current=2)
    assert w.on_change(earlier, replace(earlier, armed=False), 100.0).mission_state == "ACTIVE"
    assert (
        w.on_change(AUTO_LAST, replace(AUTO_LAST, armed=False), 100.0).mission_state == "COMPLETE"
    )


def test_the_autopilot_leaving_auto_on_the_last_item_finishes_it_but_our_own_change_does_not():
    hold = replace(AUTO_LAST, mode="LOITER")
    w = MissionWatch()
    w.uploaded(5)
    w.asked_mode(99.5)  # the agent paused it
    assert w.on_change(AUTO_LAST, hold, 100.0).mission_state == "ACTIVE"
    assert w.on_change(AUTO_LAST, hold, 103.0).mission_state == "COMPLETE"


def test_auto_and_armed_starts_the_mission():
    w = MissionWatch()
    w.uploaded(5)
    before = _s(mode="GUIDED", mission_state="NOT_STARTED", mission_current=0)
    assert w.on_change(before, replace(before, mode="AUTO"), 1.0).mission_state == "ACTIVE"


def test_an_autopilot_reporting_mission_state_is_believed():
    w = MissionWatch()
    w.uploaded(5)
    w.reported = True
    assert w.on_change(AUTO_LAST, replace(AUTO_LAST, armed=False), 1.0).mission_state == "ACTIVE"
    assert w.on_change(AUTO_LAST, replace(AUTO_LAST, mode="LOITER"), 9.0).mission_state == "ACTIVE"
    done = replace(AUTO_LAST, mission_state="COMPLETE")
    assert w.on_change(AUTO_LAST, done, 10.0).mission_state == "COMPLETE"


# the survey's shape: takeoff, speed, waypoints, RTL (server numbering)
SURVEY = [22, 178, 16, 16, 16, 20]
ON_RTL = _s(mode="AUTO", mission_current=5, mission_total=6, mission_state="ACTIVE", alt_rel=20)


@pytest.mark.parametrize("reported", [False, True])
def test_reaching_the_last_item_finishes_even_when_the_autopilot_reports_mission_state(reported):
    w = MissionWatch()
    w.uploaded(6, SURVEY)
    w.reported = reported  # ArduPilot 4.4+ sends mission_state too
    assert w.on_reached(ON_RTL, 5).mission_state == "ACTIVE"  # item 4
    assert w.on_reached(ON_RTL, 6).mission_state == "COMPLETE"


@pytest.mark.parametrize("reported", [False, True])
def test_a_final_rtl_item_starting_finishes_the_mission(reported):
    w = MissionWatch()
    w.uploaded(6, SURVEY)
    w.reported = reported
    flying = replace(ON_RTL, mission_current=4)
    assert w.on_change(flying, flying, 1.0).mission_state == "ACTIVE"
    assert w.on_change(flying, ON_RTL, 2.0).mission_state == "COMPLETE"
    assert w.finished == "the last item (RTL) started"


def test_a_final_land_item_starting_finishes_it_but_a_last_waypoint_or_an_earlier_rtl_does_not():
    w = MissionWatch()
    w.uploaded(4, [22, 16, 16, 21])
    on_land = replace(ON_RTL, mission_current=3, mission_total=4)
    before = replace(on_land, mission_current=2)
    assert w.on_change(before, before, 1.0).mission_state == "ACTIVE"
    assert w.on_change(before, on_land, 2.0).mission_state == "COMPLETE"
    w = MissionWatch()
    w.uploaded(4, [22, 20, 16, 16])
    for current in (1, 3):  # an RTL in the middle; the last waypoint, flown to
        s = replace(ON_RTL, mission_current=current, mission_total=4)
        assert w.on_change(s, s, 1.0).mission_state == "ACTIVE"


def test_a_stale_last_item_at_the_start_of_a_new_flight_is_not_the_end():
    # the autopilot still names the last flight's last item when AUTO starts the new upload
    w = MissionWatch()
    w.uploaded(6, SURVEY)
    on_the_lift = replace(ON_RTL, mode="GUIDED", alt_rel=0.0, mission_state="NOT_STARTED")
    assert w.on_change(on_the_lift, ON_RTL, 1.0).mission_state == "ACTIVE"
    first = replace(ON_RTL, mission_current=0)
    assert w.on_change(ON_RTL, first, 1.5).mission_state == "ACTIVE"
    assert w.finished is None


def test_the_last_navigation_item_counts_not_trailing_do_commands():
    w = MissionWatch()
    w.uploaded(5, [22, 16, 16, 16, 183])  # ... DO_SET_SERVO after the last waypoint
    s = replace(ON_RTL, mission_current=3, mission_total=5)
    assert w.on_reached(s, 3).mission_state == "ACTIVE"
    assert w.on_reached(s, 4).mission_state == "COMPLETE"


def test_our_own_rtl_on_the_way_to_the_last_waypoint_is_an_abort_not_the_end():
    w = MissionWatch()
    w.uploaded(4, [22, 16, 16, 16])
    to_last = replace(ON_RTL, mission_current=3, mission_total=4)
    w.asked_mode(10.0)  # Autopilot.return_to_base
    rtl = replace(to_last, mode="RTL", mission_state="PAUSED")
    assert w.on_change(to_last, rtl, 10.5).mission_state == "PAUSED"
    assert w.finished is None


def test_finished_stays_finished_until_a_restart_or_a_new_upload():
    w = MissionWatch()
    w.uploaded(6, SURVEY)
    w.reported = True
    last_leg = replace(ON_RTL, mission_current=4)
    assert w.on_change(last_leg, ON_RTL, 1.0).mission_state == "COMPLETE"
    # the run switches to RTL: ArduPilot stops AP_Mission, MISSION_CURRENT says NOT_STARTED
    rtl = replace(ON_RTL, mode="RTL", mission_state="NOT_STARTED")
    assert w.on_change(ON_RTL, rtl, 2.0).mission_state == "COMPLETE"
    landed = replace(rtl, armed=False, alt_rel=0.0)
    assert w.on_change(rtl, landed, 30.0).mission_state == "COMPLETE"
    # started again from the first item in AUTO: a new flight of the same mission
    again = replace(ON_RTL, mission_current=0, mission_state="ACTIVE")
    assert w.on_change(landed, again, 60.0).mission_state == "ACTIVE"
    assert w.finished is None
    assert w.on_change(again, ON_RTL, 90.0).mission_state == "COMPLETE"
    w.uploaded(6, SURVEY)
    assert w.finished is None


def test_one_mission_finished_event_for_a_final_rtl_whatever_the_autopilot_says_after():
    w, tracker = MissionWatch(), EventTracker()
    w.uploaded(6, SURVEY)
    w.reported = True
    prev = replace(ON_RTL, mission_current=4)
    kinds: list[str] = []
    for cur in (
        prev,
        ON_RTL,  # the RTL item starts
        replace(ON_RTL, mission_state="ACTIVE"),  # the autopilot: still running
        replace(ON_RTL, mode="RTL", mission_state="NOT_STARTED"),  # the run's RTL stops it
        replace(ON_RTL, mode="RTL", mission_state="COMPLETE"),
    ):
        state = w.on_change(prev, cur, 1.0)
        kinds += [e.kind for e in tracker.update(state)]
        prev = cur
    assert kinds.count("mission_finished") == 1, kinds
