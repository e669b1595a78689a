"""Simulated weather: a seedable random process (wind, gusts, rain spells, temperature, humidity).

Wind is a mean speed following a slow Ornstein-Uhlenbeck process around `wind_mean_mps`
plus a fast gust component (the anemometer's own turbulence) and occasional gust events; the
direction (degrees FROM which the wind blows, meteorological convention) wanders slowly.
`wind_ne` is what the anemometer feels; `flow_ne` is the wind without its turbulence, which the
vehicle's own (sim/wind.py `Airflow`: shear and Dryden turbulence at its height) rides on. Rain comes in spells: a two-state
Markov chain (dry/raining) with a random rate per spell. Temperature follows a daily
sinusoid plus noise; humidity rises when it rains and falls when it is warm.

`WIND_GUST` semantics: the maximum instantaneous wind speed over the last 10 simulated
seconds. Any value may be forced (`force(...)`); scripted scenarios (`SCENARIOS`) are
timed lists of forced values. All randomness comes from one `random.Random(seed)`.
"""

from __future__ import annotations

import math
import random
from collections import deque
from dataclasses import dataclass, field, replace

from sim.wind import Gust, from_direction

GUST_WINDOW_S = 10.0
STEP_S = 0.25


@dataclass(frozen=True)
class WeatherReading:
    """What the base's weather sensors report at one instant (SI-ish units)."""

    wind_mps: float
    gust_mps: float
    direction_deg: float
    rain_mm_h: float
    temperature_c: float
    humidity_pct: float
    sensor_fault: bool = False


@dataclass(frozen=True)
class Forced:
    """Values forced by a test or scenario; None leaves the random process in charge."""

    wind_mps: float | None = None
    gust_mps: float | None = None
    direction_deg: float | None = None
    rain_mm_h: float | None = None
    temperature_c: float | None = None
    humidity_pct: float | None = None


@dataclass(frozen=True)
class WeatherParams:
    """Climate of the simulated site."""

    wind_mean_mps: float = 3.0
    wind_sigma_mps: float = 1.0
    gust_sigma_mps: float = 0.8
    gust_event_per_h: float = 20.0
    gust_event_mps: float = 4.0
    rain_spells_per_day: float = 2.0
    rain_spell_mean_h: float = 1.0
    temperature_mean_c: float = 16.0
    temperature_amplitude_c: float = 5.0
    start_hour: float = 12.0


# name -> list of (seconds after the scenario starts, forced values from then on)
SCENARIOS: dict[str, list[tuple[float, Forced]]] = {
    "calm": [(0.0, Forced(wind_mps=1.0, gust_mps=1.5, rain_mm_h=0.0, temperature_c=18.0))],
    "windy": [(0.0, Forced(wind_mps=9.0, gust_mps=14.0, rain_mm_h=0.0))],
    "storm": [
        (0.0, Forced(wind_mps=6.0, gust_mps=9.0, rain_mm_h=0.0)),
        (60.0, Forced(wind_mps=12.0, gust_mps=18.0, rain_mm_h=8.0)),
        (600.0, Forced(wind_mps=4.0, gust_mps=6.0, rain_mm_h=0.5)),
    ],
    "rain_spell": [
        (0.0, Forced(rain_mm_h=3.0)),
        (300.0, Forced(rain_mm_h=0.0)),
    ],
    "freezing": [(0.0, Forced(temperature_c=-8.0, humidity_pct=85.0))],
}


@dataclass
class _State:
    t: float = 0.0
    mean_wind: float = 3.0
    gust: float = 0.0
    gust_event: float = 0.0
    direction: float = 270.0
    raining: bool = False
    rain_rate: float = 0.0
    temp_noise: float = 0.0
    history: deque[tuple[float, float]] = field(default_factory=deque)


class Weather:
    """The weather process; advance it with `advance_to(t_sim)` and read `reading()`."""

    def __init__(self, seed: int = 0, params: WeatherParams | None = None) -> None:
        self.params = params or WeatherParams()
        self._rng = random.Random(seed)
        self._s = _State(mean_wind=self.params.wind_mean_mps)
        self._s.direction = self._rng.uniform(0.0, 360.0)
        self.forced = Forced()
        self.sensor_fault = False
        self._scenario: list[tuple[float, Forced]] = []
        self.gusts: list[Gust] = []  # discrete gusts scheduled by `gust()` (sim/wind.py)

    # --- control -------------------------------------------------------------------------

    def force(self, **values: float | None) -> None:
        """Force some values (keyword names of `Forced`); None releases one value."""
        self.forced = replace(self.forced, **values)

    def gust(
        self, peak_mps: float, direction_deg: float, duration_s: float = 4.0, in_s: float = 0.0
    ) -> Gust:
        """Schedule a discrete 1 - cosine gust (sim/wind.py) `in_s` simulated seconds from now."""
        g = Gust(self._s.t + in_s, peak_mps, direction_deg, duration_s)
        self.gusts.append(g)
        return g

    def release(self) -> None:
        """Release every forced value and stop any scenario."""
        self.forced = Forced()
        self._scenario = []

    def run_scenario(self, name: str) -> None:
        """Start a scripted scenario from `SCENARIOS` at the current simulated time."""
        if name not in SCENARIOS:
            raise KeyError(f"unknown weather scenario {name!r}; known: {sorted(SCENARIOS)}")
        self._scenario = [(self._s.t + dt, f) for dt, f in SCENARIOS[name]]
        self._apply_scenario()

    def _apply_scenario(self) -> None:
        while self._scenario and self._scenario[0][0] <= self._s.t:
            _, forced = self._scenario.pop(0)
            self.forced = forced

    # --- process -------------------------------------------------------------------------

    @property
    def t(self) -> float:
        """Simulated time the process has reached."""
        return self._s.t

    def advance_to(self, t_sim: float) -> None:
        """Run the random process forward to simulated time `t_sim` (no-op if in the past)."""
        while self._s.t + STEP_S <= t_sim:
            self._step(STEP_S)

    def _step(self, dt: float) -> None:
        p, s, rng = self.params, self._s, self._rng
        s.t += dt
        # slow mean wind: OU with 10 min time constant
        tau = 600.0
        s.mean_wind += (p.wind_mean_mps - s.mean_wind) * dt / tau + p.wind_sigma_mps * math.sqrt(
            2 * dt / tau
        ) * rng.gauss(0, 1)
        s.mean_wind = max(0.0, s.mean_wind)
        # fast turbulence: OU with 3 s time constant
        tau_g = 3.0
        s.gust += -s.gust * dt / tau_g + p.gust_sigma_mps * math.sqrt(2 * dt / tau_g) * rng.gauss(
            0, 1
        )
        # gust events: sudden rise decaying over ~4 s
        if rng.random() < p.gust_event_per_h * dt / 3600.0:
            s.gust_event = rng.uniform(0.5, 1.0) * p.gust_event_mps
        s.gust_event *= math.exp(-dt / 4.0)
        s.direction = (s.direction + rng.gauss(0, 1.0) * math.sqrt(dt)) % 360.0
        # rain spells
        if s.raining:
            if rng.random() < dt / (p.rain_spell_mean_h * 3600.0):
                s.raining, s.rain_rate = False, 0.0
        elif rng.random() < p.rain_spells_per_day * dt / 86400.0:
            s.raining, s.rain_rate = True, rng.expovariate(1 / 2.0) + 0.2
        s.temp_noise += -s.temp_noise * dt / 900.0 + 0.3 * math.sqrt(2 * dt / 900.0) * rng.gauss(
            0, 1
        )
        self._apply_scenario()
        wind = self._wind_now()
        s.history.append((s.t, wind))
        while s.history and s.history[0][0] < s.t - GUST_WINDOW_S:
            s.history.popleft()

    def _wind_now(self) -> float:
        if self.forced.wind_mps is not None:
            return self.forced.wind_mps
        s = self._s
        return max(0.0, s.mean_wind + s.gust + s.gust_event)

    def _temperature(self) -> float:
        p, s = self.params, self._s
        hour = (p.start_hour + s.t / 3600.0) % 24.0
        # warmest at 15:00
        daily = p.temperature_amplitude_c * math.cos(2 * math.pi * (hour - 15.0) / 24.0)
        return p.temperature_mean_c + daily + s.temp_noise - (2.0 if s.raining else 0.0)

    def reading(self) -> WeatherReading:
        """What the sensors report now (forced values win)."""
        f, s = self.forced, self._s
        wind = self._wind_now()
        gust = max([w for _, w in s.history] + [wind])
        if f.gust_mps is not None:
            gust = max(f.gust_mps, wind)
        rain = f.rain_mm_h if f.rain_mm_h is not None else s.rain_rate
        temp = f.temperature_c if f.temperature_c is not None else self._temperature()
        humidity = 60.0 - 1.5 * (temp - 16.0) + (30.0 if rain > 0 else 0.0)
        if f.humidity_pct is not None:
            humidity = f.humidity_pct
        direction = f.direction_deg if f.direction_deg is not None else s.direction
        return WeatherReading(
            wind_mps=wind,
            gust_mps=gust,
            direction_deg=direction % 360.0,
            rain_mm_h=max(0.0, rain),
            temperature_c=temp,
            humidity_pct=min(100.0, max(0.0, humidity)),
            sensor_fault=self.sensor_fault,
        )

    def wind_ne(self, t_sim: float) -> tuple[float, float]:
        """Air velocity (north, east) in m/s at `t_sim` (mean + turbulence + gust events, and
        the discrete gusts scheduled by `gust()`), blowing FROM the direction."""
        self.advance_to(t_sim)
        r = self.reading()
        return self._with_gusts(t_sim, from_direction(r.wind_mps, r.direction_deg))

    def _with_gusts(self, t_sim: float, wind_ne: tuple[float, float]) -> tuple[float, float]:
        n, e = wind_ne
        self.gusts = [g for g in self.gusts if not g.over(t_sim)]
        for g in self.gusts:
            gn, ge = from_direction(g.speed(t_sim), g.direction_deg)
            n, e = n + gn, e + ge
        return n, e

    def flow_ne(self, t_sim: float) -> tuple[float, float]:
        """The wind the vehicle's own turbulence rides on (sim/wind.py `Airflow`): as `wind_ne`
        but without the anemometer's turbulence (the mean, the gust events, the scheduled
        discrete gusts), 20 ft above the ground, (north, east) m/s."""
        self.advance_to(t_sim)
        s, f = self._s, self.forced
        speed = f.wind_mps if f.wind_mps is not None else max(0.0, s.mean_wind + s.gust_event)
        direction = f.direction_deg if f.direction_deg is not None else s.direction
        return self._with_gusts(t_sim, from_direction(speed, direction))

    def raining(self) -> bool:
        """Whether rain is falling now."""
        return self.reading().rain_mm_h > 0.0
