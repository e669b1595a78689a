"""Wind on the simulated vehicle: discrete 1 - cosine gusts, the shear and Dryden turbulence at
its height, and what a copter leaning at most ANGLE_MAX can hold."""

from __future__ import annotations

import itertools
import math
import random
import statistics

import pytest

from sim.vehicle.dynamics import Dynamics, DynamicsParams
from sim.weather import Weather
from sim.wind import Airflow, Dryden, Gust, dryden_scales, from_direction, shear


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
    assert w.flow_ne(1.0) == before  # forced: no anemometer turbulence either way
    peak = w.wind_ne(4.0)  # mid-gust: 18 m/s from the east on top
    assert math.isclose(peak[0], -5.0) and math.isclose(peak[1], -18.0, rel_tol=0.05)
    assert w.flow_ne(4.0) == peak
    assert w.wind_ne(7.0) == before and w.gusts == []  # passed and forgotten


def test_the_flow_the_vehicle_feels_leaves_out_the_anemometers_turbulence():
    w = Weather(seed=4)
    anemometer, flow = [], []
    for k in range(1, 2400):  # 10 min
        anemometer.append(math.hypot(*w.wind_ne(k * 0.25)))
        flow.append(math.hypot(*w.flow_ne(k * 0.25)))
    assert abs(statistics.fmean(anemometer) - statistics.fmean(flow)) < 0.5

    def steps(xs: list[float]) -> float:
        return statistics.fmean(abs(a - b) for a, b in itertools.pairwise(xs))

    assert steps(flow) < 0.3 * steps(anemometer)


def test_dryden_scales_and_intensities_at_low_altitude():
    s = dryden_scales(10.0, 12.0)  # MIL-HDBK-1797 at 10 m (32.8 ft), W20 = 12 m/s
    assert math.isclose(s.sigma_w, 1.2)
    assert 2.2 < s.sigma_u < 2.35 and s.sigma_v == s.sigma_u
    assert 64 < s.length_u < 70 and s.length_v == s.length_u / 2
    assert math.isclose(s.length_w, 5.0, rel_tol=0.01)
    low = dryden_scales(0.5, 12.0)  # below 10 ft it is evaluated at 10 ft
    assert low == dryden_scales(10 * 0.3048, 12.0)
    assert dryden_scales(10.0, 0.0).sigma_u == 0.0


def test_dryden_turbulence_has_its_intensities_and_correlation_time():
    scales = dryden_scales(10.0, 8.0)
    d = Dryden(random.Random(1))
    dt, speed = 0.02, 8.0
    samples = [d.step(dt, scales, speed) for _ in range(200_000)]  # 4000 s
    for i, sigma in enumerate((scales.sigma_u, scales.sigma_v, scales.sigma_w)):
        std = statistics.pstdev(x[i] for x in samples)
        assert 0.88 * sigma < std < 1.12 * sigma, (i, std, sigma)
    # the longitudinal component is first order: correlation e^-1 after L_u / V
    lag = round(scales.length_u / speed / dt)
    u = [x[0] for x in samples]
    corr = statistics.correlation(u[:-lag], u[lag:])
    assert 0.25 < corr < 0.5, corr
    # the vertical one decorrelates far sooner (its scale is h / 2)
    w = [x[2] for x in samples]
    assert statistics.correlation(w[:-lag], w[lag:]) < 0.1


def test_the_airflow_at_the_vehicle_shears_with_height_and_is_seeded():
    assert math.isclose(shear(20 * 0.3048), 1.0)
    assert shear(11.0) > 1.1 and 0.6 < shear(1.25) < 0.7
    calm = Airflow(seed=1)
    assert calm.step(0.01, (0.0, 0.0), 10.0) == (0.0, 0.0, 0.0)
    a, b = Airflow(seed=2), Airflow(seed=2)
    ra = [a.step(0.01, (0.0, 8.0), 10.0) for _ in range(100)]
    assert ra == [b.step(0.01, (0.0, 8.0), 10.0) for _ in range(100)]
    # over 10 min the mean wind 10 m above the pad (11 m above the ground) is 1.12 x W20, at the
    # pad's seat (1.25 m) 0.67 x W20; turbulence along and across it, and vertical
    for height, k in ((10.0, 1.12), (0.25, 0.67)):
        air = Airflow(seed=4)
        xs = [air.step(0.05, (0.0, 8.0), height) for _ in range(12_000)]
        assert statistics.fmean(x[1] for x in xs) == pytest.approx(8.0 * k, abs=0.6)
        assert all(statistics.pstdev(x[i] for x in xs) > 0.2 for i in range(3))


def _hover(wind_ne, seconds=30.0, dt=0.01):
    dyn = Dynamics(DynamicsParams())
    dyn.motors_on = True
    dyn.set_position_target((0.0, 0.0, -10.0))
    for _ in range(int(20 / dt)):
        dyn.step(dt)
    for _ in range(int(seconds / dt)):
        dyn.step(dt, wind_ne)
    return dyn


def test_a_steady_wind_is_held_leaning_into_it_and_one_beyond_the_lean_limit_is_not():
    dyn = _hover((0.0, 12.0))  # 12 m/s towards the east
    s = dyn.state
    assert math.hypot(s.position[0], s.position[1]) < 0.05  # held
    lean = math.degrees(math.hypot(s.roll, s.pitch))
    assert math.isclose(lean, dyn.hold_lean_deg(12.0), abs_tol=0.5) and 20 < lean < 25
    strong = _hover((0.0, 18.0), seconds=10.0)  # needs 37 degrees, ANGLE_MAX is 30
    st = strong.state
    assert st.position[1] > 10.0 and st.velocity[1] > 2.0  # carried downwind
    assert math.degrees(math.hypot(st.roll, st.pitch)) == pytest.approx(30.0, abs=0.5)


def test_a_gust_beyond_what_the_lean_holds_carries_it_downwind():
    def drift(peak: float) -> float:
        dyn = _hover((0.0, 0.0), seconds=0.1, dt=0.05)
        gust = Gust(0.0, peak, 270.0, 4.0)
        worst = 0.0
        for k in range(200):
            dyn.step(0.05, from_direction(gust.speed(k * 0.05), 270.0))
            worst = max(worst, dyn.state.position[1])
        return worst

    assert drift(10.0) < 1.5  # a gust it can lean into: the controller holds it within metres
    assert drift(25.0) > 8.0  # one it cannot: carried downwind
