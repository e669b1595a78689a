"""The energy to get home against the wind (server/runs/reserve.py) and the run's exit on it."""

from __future__ import annotations

import pytest

from server.missions.geometry import LocalProjection
from server.runs.machine import Observations, State, advance
from server.runs.reserve import (
    ReturnModel,
    home_reach,
    return_model,
    return_need_pct,
)

BASE = (41.178, -8.596)
NORTH_400 = (*LocalProjection(*BASE).to_geo(0.0, 400.0), 15.0)  # 400 m north, 15 m up
MODEL = ReturnModel(cruise_mps=8.0, consumption_pct_per_s=0.1, reserve_pct=20.0)


def test_a_headwind_home_costs_more_than_calm_and_a_tailwind_less():
    calm = return_need_pct(NORTH_400, BASE, None, None, MODEL)
    assert calm == pytest.approx((400 / 8 + 15 / 1.5 + 30) * 0.1)  # 9.0 %
    # wind FROM the south: blowing north, against a UAV flying home southwards
    head = return_need_pct(NORTH_400, BASE, 6.0, 180.0, MODEL)
    assert head == pytest.approx((400 / 2 + 10 + 30) * 0.1)  # ground speed 2 m/s: 24.0 %
    tail = return_need_pct(NORTH_400, BASE, 6.0, 0.0, MODEL)
    assert tail == pytest.approx((400 / 14 + 10 + 30) * 0.1)
    storm = return_need_pct(NORTH_400, BASE, 12.0, 180.0, MODEL)
    assert storm == pytest.approx((400 / 1 + 10 + 30) * 0.1)  # never below 1 m/s over ground
    # with 40 % left: calm leaves 11 % above the reserve, the headwind would eat 4 % into it
    assert home_reach(40.0, NORTH_400, BASE, None, None, MODEL).margin_pct == pytest.approx(11.0)
    assert home_reach(40.0, NORTH_400, BASE, 6.0, 180.0, MODEL).margin_pct == pytest.approx(-4.0)


def test_the_uavs_attributes_set_the_model():
    class Mission:
        speed_mps = 6.0

    m = return_model({"consumption_pct_per_s": 0.2, "battery_reserve_pct": 25, "x": 1}, Mission())
    assert (m.consumption_pct_per_s, m.reserve_pct, m.cruise_mps) == (0.2, 25.0, 6.0)
    assert return_model({"consumption_pct_per_s": "lots"}, None) == ReturnModel()


def test_the_run_turns_home_at_the_reserve_only_once_airborne():
    def obs(margin: float, took_off: bool) -> Observations:
        return Observations(
            elapsed_s=5, timeout_s=100, commands={}, return_margin_pct=margin, took_off=took_off
        )

    t = advance(State.flying, obs(-0.5, True))
    assert t is not None and t.to == State.landing and t.cause == "battery_reserve" and t.alert
    assert "-0.5" in t.reason
    assert advance(State.flying, obs(3.0, True)) is None
    assert advance(State.flying, obs(-0.5, False)) is None  # still on the lift: not this exit


def test_home_is_out_of_reach_when_the_return_would_land_below_the_critical_level():
    """Issue 48 finding 3: 15 m/s from the south, 400 m north of the base: the return is flown at
    the model's 1 m/s over ground (460 s at 0.1 %/s: 44 %); with 40 % left it would land at -4 %."""
    storm = home_reach(40.0, NORTH_400, BASE, 15.0, 180.0, MODEL)
    assert storm.need_pct == pytest.approx(44.0)
    assert storm.margin_pct == pytest.approx(40.0 - 44.0 - 20.0)
    assert storm.out_of_reach
    calm = home_reach(40.0, NORTH_400, BASE, None, None, MODEL)
    assert not calm.out_of_reach and calm.margin_pct == pytest.approx(11.0)
    # below the reserve but above the critical level: home is still in reach (the reserve's job)
    tight = home_reach(16.0, NORTH_400, BASE, None, None, MODEL)  # would land with 7 %
    assert tight.margin_pct < 0 and not tight.out_of_reach
    assert return_model({"battery_critical_pct": 8}, None).critical_pct == 8.0
    # over the base with 6 % and the descent and landing to pay (4 %): it lands home, not away
    over_base = home_reach(6.0, (*BASE, 10.0), BASE, 15.0, 180.0, MODEL)
    assert over_base.need_pct == pytest.approx((10 / 1.5 + 30) * 0.1)
    assert 6.0 - over_base.need_pct < MODEL.critical_pct and not over_base.out_of_reach


def test_a_uav_that_cannot_reach_home_is_landed_where_it_is_with_an_alert():
    def obs(**kw) -> Observations:  # type: ignore[no-untyped-def]
        # the landing step's own events: the take-off was the flying step's
        return Observations(elapsed_s=5, timeout_s=100, commands={}, **kw)

    far = {"home_out_of_reach": True, "home_need_pct": 61.4, "battery_pct": 22.0}
    t = advance(State.landing, obs(**far))
    assert t is not None and t.to == State.failed and t.cause == "home_out_of_reach" and t.alert
    assert [(a.target, a.name) for a in t.extra_actions] == [("uav", "land")]
    assert "61 % of its 22 %" in t.reason and "with -39 %" in t.reason, t.reason
    assert "landing where it is" in t.reason
    assert advance(State.landing, obs(**{**far, "home_out_of_reach": False})) is None
    # landed already (where it is, or home): the landing's own exits, not this one
    landed = advance(State.landing, obs(**far, uav_landed=True))
    assert landed is not None and landed.cause != "home_out_of_reach"
