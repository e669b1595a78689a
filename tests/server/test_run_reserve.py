"""The energy to get home against the wind (server/runs/reserve.py) and the run's exit on it."""

from __future__ import annotations

import pytest

from server.missions.geometry import LocalProjection
from server.runs.machine import Observations, State, advance
from server.runs.reserve import ReturnModel, return_margin_pct, return_model, return_need_pct

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
    assert return_margin_pct(40.0, NORTH_400, BASE, None, None, MODEL) == pytest.approx(11.0)
    assert return_margin_pct(40.0, NORTH_400, BASE, 6.0, 180.0, MODEL) == pytest.approx(-4.0)


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
