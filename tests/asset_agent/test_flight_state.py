"""Each inference of asset_agent/autopilot/flight_state.py: landed state and mission completion
for autopilots that send no EXTENDED_SYS_STATE and no MISSION_CURRENT.mission_state."""

from __future__ import annotations

from dataclasses import replace

import pytest

from asset_agent.autopilot.flight_state import MissionWatch, infer_landed_state
from asset_agent.autopilot.state import UavState

GROUND = UavState(link_up=True, armed=True, system_status=4, mode="GUIDED", alt_rel=0.0, vd=0.0)


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


def test_still_below_a_metre_after_flying_is_touched_down():
    for prev in ("IN_AIR", "LANDING", "TAKEOFF"):
        assert infer_landed_state(prev, _s(mode="LAND", alt_rel=0.1, vd=0.05)) == "ON_GROUND"
    assert infer_landed_state("LANDING", _s(mode="LAND", alt_rel=0.5, vd=0.5)) == "LANDING"


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
    assert (
        w.on_change(AUTO_LAST, replace(AUTO_LAST, armed=False), 100.0).mission_state == "COMPLETE"
    )
    earlier = replace(AUTO_LAST, mission_current=2)
    assert w.on_change(earlier, replace(earlier, armed=False), 100.0).mission_state == "ACTIVE"


def test_the_autopilot_leaving_auto_on_the_last_item_finishes_it_but_our_own_change_does_not():
    w = MissionWatch()
    w.uploaded(5)
    hold = replace(AUTO_LAST, mode="LOITER")
    assert w.on_change(AUTO_LAST, hold, 100.0).mission_state == "COMPLETE"
    w.asked_mode(99.5)  # the agent paused it
    assert w.on_change(AUTO_LAST, hold, 100.0).mission_state == "ACTIVE"


def test_auto_and_armed_starts_the_mission():
    w = MissionWatch()
    w.uploaded(5)
    before = _s(mode="GUIDED", mission_state="NOT_STARTED", mission_current=0)
    assert w.on_change(before, replace(before, mode="AUTO"), 1.0).mission_state == "ACTIVE"


def test_an_autopilot_reporting_mission_state_is_believed():
    w = MissionWatch()
    w.uploaded(5)
    w.reported = True
    assert w.on_reached(AUTO_LAST, 5).mission_state == "ACTIVE"
    assert w.on_change(AUTO_LAST, replace(AUTO_LAST, armed=False), 1.0).mission_state == "ACTIVE"
