"""The precision-landing evaluation's wind: the simulated world's own model, set per trial.

A trial's weather is `sim.weather.Weather` forced to the scenario's mean wind (the wind 20 ft above
the ground, W20) from a direction drawn from the trial's seed, with one discrete 1 - cosine gust
(`Weather.gust`, sim/wind.py) of the scenario's peak, `GUST_S` long, from within 45 degrees of
the mean wind, at a moment drawn between 5 and 25 s into the descent. The vehicle feels that
wind through its own `sim.wind.Airflow`, exactly as in the world: sheared to its height (MIL-F-
8785C's logarithmic profile, the pad 1 m above the ground) with Dryden turbulence at W20 along,
across and below it. The simulated autopilot (`sim.vehicle.copter.Copter.tick`) carries its own
`Airflow`; the evaluation's `SharedVehicle` carries one too.

`WIND_ROWS`: scenarios flying the fused sensors (marker + IR) at 0, 5, 8 and 12 m/s with a gust
of half the mean on top; `THESIS_FIELD`: the MSc thesis's field trial as our README quotes it
(marker and IR fused, "windy", no RTK) with what the paper (§4) says the field did to the camera.
"""

from __future__ import annotations

import random
from dataclasses import dataclass

from sim.weather import Weather

GUST_S = 3.0  # the discrete gust's length
GUST_WINDOW_S = (5.0, 25.0)  # when it comes, seconds after the trial starts


@dataclass(frozen=True)
class TrialWind:
    """One trial's wind as drawn from its seed: mean speed and direction (FROM, degrees), the
    gust's peak, direction and start."""

    wind_mps: float
    direction_deg: float
    gust_mps: float
    gust_direction_deg: float
    gust_start_s: float


def draw(wind_mps: float, gust_mps: float, seed: int) -> TrialWind:
    """The trial's wind, from its own generator (the trial's other random streams unchanged)."""
    rng = random.Random(f"{seed}/wind")
    direction = rng.uniform(0.0, 360.0)
    return TrialWind(
        wind_mps,
        direction,
        gust_mps,
        (direction + rng.uniform(-45.0, 45.0)) % 360.0,
        rng.uniform(*GUST_WINDOW_S),
    )


def trial_weather(wind_mps: float, gust_mps: float, seed: int) -> Weather:
    """The weather of one trial (its `flow_ne(t)` is the wind 20 ft above the ground)."""
    w = draw(wind_mps, gust_mps, seed)
    weather = Weather(seed)
    weather.force(wind_mps=w.wind_mps, direction_deg=w.direction_deg)
    if w.gust_mps > 0:
        weather.gust(w.gust_mps, w.gust_direction_deg, GUST_S, in_s=w.gust_start_s)
    return weather
