"""The precision-landing evaluation's wind: the simulated world's own model, set per trial.

A trial's weather is `sim.weather.Weather` forced to the scenario's mean wind (the wind 20 ft above
the ground, W20) from a direction drawn from the trial's seed, with one discrete 1 - cosine gust
(`Weather.gust`, sim/wind.py) of the scenario's peak, `GUST_S` long, from within 45 degrees of
the mean wind, at a moment drawn between 5 and 25 s into the descent. The vehicle feels that
wind through its own `sim.wind.Airflow`, exactly as in the world: sheared to its height (MIL-F-
8785C's logarithmic profile, the pad 1 m above the ground) with Dryden turbulence at W20 along,
across and below it. The simulated autopilot (`sim.vehicle.copter.Copter.tick`) carries its own
`Airflow`; the evaluation's `SharedVehicle` carries one too.

The scenarios that use it are in `precland_eval.py` (fused-wind0/5/8/12, thesis-field).
`python bench/precland_wind.py` prints what the copter does in these winds: the lean that holds
each steady wind, and how far it strays holding a position 10 m and 1 m above the pad for 40 s.
"""

from __future__ import annotations

import math
import random
import statistics
import sys
from dataclasses import dataclass, replace
from pathlib import Path

if __name__ == "__main__":  # run as a script from a checkout
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from sim.vehicle.dynamics import Dynamics
from sim.weather import Weather
from sim.wind import Airflow

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


def hold(wind_mps: float, height_m: float, seed: int, seconds: float = 40.0) -> tuple[float, float]:
    """Hold a position `height_m` above the pad in a trial's wind (gust of half the mean): the
    largest distance strayed (m, after the first 3 s) and the share of the time at ANGLE_MAX."""
    dyn = Dynamics()
    dyn.motors_on = True
    dyn.state = replace(dyn.state, position=(0.0, 0.0, -height_m), landed=False)
    dyn.set_position_target((0.0, 0.0, -height_m))
    air, weather = Airflow(seed=seed), trial_weather(wind_mps, wind_mps / 2, seed)
    dt, worst, limited, n = 0.01, 0.0, 0, 0
    for k in range(round(seconds / dt)):
        st = dyn.state
        a = air.step(dt, weather.flow_ne(k * dt), st.altitude, (st.velocity[0], st.velocity[1]))
        st = dyn.step(dt, (a[0], a[1]))
        if k * dt > 3.0:
            n += 1
            worst = max(worst, math.hypot(st.position[0], st.position[1]))
            lean = math.degrees(math.hypot(st.roll, st.pitch))
            limited += lean > dyn.params.angle_max_deg - 0.5
    return worst, limited / n


def main() -> int:
    """Print the lean each steady wind needs and how the copter holds in the trials' winds."""
    dyn = Dynamics()
    print(f"ANGLE_MAX {dyn.params.angle_max_deg:g}°, holds {dyn.params.max_airspeed_mps:g} m/s")
    print("steady wind m/s -> lean °: " + ", ".join(
        f"{w} -> {dyn.hold_lean_deg(w):.1f}" for w in (2, 5, 8, 12, 15)
    ))  # fmt: skip
    print("holding a position 40 s, seeds 1000-1009, W20 with a gust of W20/2:")
    print(
        f"{'W20 m/s':>8}{'height m':>10}{'strayed cm, median':>20}{'worst':>8}{'at ANGLE_MAX':>14}"
    )
    for w in (5.0, 8.0, 12.0):
        for h in (10.0, 1.0):
            runs = [hold(w, h, seed) for seed in range(1000, 1010)]
            strayed = [100 * r[0] for r in runs]
            limited = 100 * statistics.fmean(r[1] for r in runs)
            print(
                f"{w:>8g}{h:>10g}{statistics.median(strayed):>20.0f}{max(strayed):>8.0f}"
                f"{limited:>13.1f}%"
            )
    return 0


if __name__ == "__main__":
    sys.exit(main())
