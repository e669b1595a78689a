"""Each inference of asset_agent/autopilot/flight_state.py: the landed state for autopilots that
send no EXTENDED_SYS_STATE (mission completion: test_mission_watch.py)."""

from __future__ import annotations

from dataclasses import replace

import pytest

from asset_agent.autopilot.flight_state import infer_landed_state
from asset_agent.autopilot.state import UavState

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
