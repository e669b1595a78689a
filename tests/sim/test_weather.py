"""Weather process: seedable, gust is a 10 s max, forced values and scenarios win."""

from __future__ import annotations

import math

from sim.weather import Weather, WeatherParams


def test_same_seed_same_weather() -> None:
    a, b = Weather(seed=3), Weather(seed=3)
    a.advance_to(600)
    b.advance_to(600)
    assert a.reading() == b.reading()


def test_gust_is_max_of_last_10_s() -> None:
    w = Weather(seed=5)
    peak_history = []
    for i in range(1, 400):
        w.advance_to(i * 0.25)
        peak_history.append((w.t, w.reading().wind_mps))
        recent = [s for t, s in peak_history if t > w.t - 10.0 + 1e-9]
        assert math.isclose(w.reading().gust_mps, max(recent), rel_tol=1e-9) or (
            w.reading().gust_mps >= max(recent)
        )
        assert w.reading().gust_mps >= w.reading().wind_mps


def test_forced_values_and_release() -> None:
    w = Weather(seed=1)
    w.force(wind_mps=12.0, rain_mm_h=4.0, gust_mps=15.0)
    w.advance_to(5)
    r = w.reading()
    assert r.wind_mps == 12.0 and r.gust_mps == 15.0 and r.rain_mm_h == 4.0
    n, e = w.wind_ne(5)
    assert math.isclose(math.hypot(n, e), 12.0)
    w.release()
    assert w.forced.wind_mps is None


def test_scenario_steps_in_time() -> None:
    w = Weather(seed=1)
    w.run_scenario("storm")
    assert w.reading().wind_mps == 6.0
    w.advance_to(61)
    assert w.reading().wind_mps == 12.0 and w.reading().rain_mm_h == 8.0


def test_rain_spells_happen_over_days() -> None:
    w = Weather(seed=2, params=WeatherParams(rain_spells_per_day=12.0, rain_spell_mean_h=0.5))
    rainy = 0
    for m in range(1, 12 * 6):
        w.advance_to(m * 600.0)
        rainy += w.raining()
    assert 0 < rainy < 12 * 6
