"""Wind on the simulated vehicle: discrete 1 - cosine gusts and wind beyond its authority."""

from __future__ import annotations

import math

from sim.vehicle.dynamics import Dynamics, DynamicsParams
from sim.weather import Weather
from sim.wind import Gust, from_direction, overpowering


def test_a_discrete_gust_rises_to_its_peak_and_dies_away():
    g = Gust(start_s=10.0, peak_mps=20.0, direction_deg=270.0, duration_s=4.0)
    assert g.speed(9.9) == 0.0 and g.speed(12.0) == 20.0 and g.speed(14.1) == 0.0
    assert math.isclose(g.speed(11.0), 10.0)
    n, e = from_direction(20.0, 270.0)  # from the west: blows towards the east
    assert math.isclose(n, 0.0, abs_tol=1e-9) and math.isclose(e, 20.0)


def test_the_weather_adds_scheduled_gusts_to_its_wind():
    w = Weather(seed=3)
    w.force(wind_mps=5.0, direction_deg=0.0)  # a steady 5 m/s from the north
    w.gust(peak_mps=18.0, direction_deg=90.0, duration_s=4.0, in_s=2.0)
    before = w.wind_ne(1.0)
    assert math.isclose(before[0], -5.0) and math.isclose(before[1], 0.0, abs_tol=1e-9)
    peak = w.wind_ne(4.0)  # mid-gust: 18 m/s from the east on top
    assert math.isclose(peak[0], -5.0) and math.isclose(peak[1], -18.0, rel_tol=0.05)
    assert w.wind_ne(7.0) == before and w.gusts == []  # passed and forgotten


def test_wind_beyond_the_vehicles_authority_carries_it_downwind():
    assert overpowering((0.0, 10.0), 15.0) == (0.0, 0.0)
    assert overpowering((0.0, 20.0), 15.0) == (0.0, 5.0)

    def drift(peak: float) -> float:
        dyn = Dynamics(DynamicsParams())
        dyn.motors_on = True
        dyn.set_position_target((0.0, 0.0, -10.0))
        for _ in range(400):
            dyn.step(0.05)
        gust = Gust(0.0, peak, 270.0, 4.0)
        worst = 0.0
        for k in range(200):
            dyn.step(0.05, from_direction(gust.speed(k * 0.05), 270.0))
            worst = max(worst, dyn.state.position[1])
        return worst

    assert drift(10.0) < 1.5  # a gust it can lean into: the controller holds it within metres
    assert drift(25.0) > 8.0  # one it cannot: carried downwind
