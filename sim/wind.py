"""Wind the simulated vehicle flies in: the weather's wind, the shear near the ground, Dryden
turbulence at the vehicle's height, and discrete gusts.

Three scales, one model shared by the simulated world and the precision-landing evaluation:

- **the weather** (`sim/weather.py`): the site's wind as the base's anemometer reads it, a mean
  wandering over minutes with gust events, settable with `Weather.force(wind_mps=,
  direction_deg=)`; `Weather.flow_ne(t)` is that wind without the anemometer's own turbulence;
- **discrete gusts** (`Gust`, scheduled by `Weather.gust(...)`): the "1 - cosine" shape of
  MIL-F-8785C's discrete gust, over `duration_s` the speed rises from 0 to `peak_mps` and back,
  `peak/2 * (1 - cos(2 pi t / duration))`, blowing FROM `direction_deg` (meteorological
  convention, as the weather's direction);
- **at the vehicle** (`Airflow`): the mean wind scaled to the vehicle's height by the
  logarithmic shear of MIL-F-8785C, `W(h) = W20 ln(h / z0) / ln(20 ft / z0)` (W20, the wind 20 ft
  = 6.1 m above the ground, is the weather's wind; z0 = 0.15 ft), plus `Dryden` turbulence: the
  low-altitude model of MIL-F-8785C / MIL-HDBK-1797 (scales and intensities from the height and
  W20, the three shaping filters driven by white noise; below 10 ft evaluated at 10 ft). The
  turbulence is a frozen field the vehicle flies through at its airspeed; a hovering vehicle has
  it carried past by the mean wind, so the speed used is the larger of the two (at least 1 m/s).

What the vehicle does with the air is `sim/vehicle/dynamics.py`: drag against thrust leaned at
most ANGLE_MAX, so a wind beyond what that lean holds carries it downwind.
"""

from __future__ import annotations

import math
import random
from dataclasses import dataclass

FT = 0.3048
W20_HEIGHT_M = 20 * FT


@dataclass(frozen=True)
class Gust:
    """A discrete 1 - cosine gust: `peak_mps` from `direction_deg`, starting at `start_s`."""

    start_s: float
    peak_mps: float
    direction_deg: float
    duration_s: float

    def speed(self, t: float) -> float:
        """The gust's speed at simulated time `t` (0 outside it)."""
        x = (t - self.start_s) / self.duration_s
        if not 0.0 <= x <= 1.0:
            return 0.0
        return self.peak_mps / 2.0 * (1.0 - math.cos(2.0 * math.pi * x))

    def over(self, t: float) -> bool:
        """True once the gust has passed."""
        return t > self.start_s + self.duration_s


def from_direction(speed_mps: float, direction_deg: float) -> tuple[float, float]:
    """Air velocity (north, east) of wind of `speed_mps` blowing FROM `direction_deg`."""
    rad = math.radians(direction_deg)
    return -speed_mps * math.cos(rad), -speed_mps * math.sin(rad)


def shear(height_m: float, z0_m: float = 0.15 * FT) -> float:
    """MIL-F-8785C's logarithmic shear: the wind at `height_m` above the ground over the wind at
    20 ft (1 at 6.1 m, 1.12 at 11 m, 0.67 at 1.25 m; evaluated no lower than 0.3 m)."""
    return math.log(max(height_m, 0.3) / z0_m) / math.log(W20_HEIGHT_M / z0_m)


@dataclass(frozen=True)
class DrydenScales:
    """Dryden's low-altitude turbulence at one height: intensities (m/s) and scale lengths (m)
    of the longitudinal (along the mean wind), lateral and vertical components."""

    sigma_u: float
    sigma_v: float
    sigma_w: float
    length_u: float
    length_v: float
    length_w: float


def dryden_scales(height_m: float, w20_mps: float) -> DrydenScales:
    """MIL-HDBK-1797 below 1000 ft: sigma_w = 0.1 W20, sigma_u = sigma_v = sigma_w /
    (0.177 + 0.000823 h)^0.4, L_u = 2 L_v = h / (0.177 + 0.000823 h)^1.2, L_w = h / 2 (h in ft,
    at least 10 ft). At 10 m and W20 = 12 m/s: sigma_u 2.3 m/s, sigma_w 1.2 m/s, L_u 67 m."""
    h = max(height_m / FT, 10.0)
    k = 0.177 + 0.000823 * h
    sigma_w = 0.1 * max(w20_mps, 0.0)
    sigma_uv = sigma_w / k**0.4
    length_u = h / k**1.2 * FT
    return DrydenScales(sigma_uv, sigma_uv, sigma_w, length_u, length_u / 2, h / 2 * FT)


class Dryden:
    """The three shaping filters of the Dryden spectra, driven by white noise from `rng`:
    longitudinal `sigma sqrt(2L/(pi V)) / (1 + L/V s)`, lateral and vertical
    `sigma sqrt(2L/(pi V)) (1 + 2 sqrt(3) L/V s) / (1 + 2L/V s)^2`. Discretised so that each
    component's stationary deviation is its sigma: the first order exactly, the second order in
    sub-steps of at most a tenth of its time constant."""

    def __init__(self, rng: random.Random) -> None:
        self._rng = rng
        self.u = 0.0  # unit-variance longitudinal state
        self._v = [0.0, 0.0]  # lateral filter states (unit-intensity input)
        self._w = [0.0, 0.0]

    def step(self, dt: float, scales: DrydenScales, speed_mps: float) -> tuple[float, float, float]:
        """Advance `dt` seconds flying through the field at `speed_mps`; (u, v, w) in m/s."""
        speed = max(speed_mps, 1.0)
        a = math.exp(-dt * speed / scales.length_u)
        self.u = a * self.u + math.sqrt(1.0 - a * a) * self._rng.gauss(0.0, 1.0)
        v = self._second_order(self._v, dt, 2.0 * scales.length_v / speed)
        w = self._second_order(self._w, dt, 2.0 * scales.length_w / speed)
        return self.u * scales.sigma_u, v * scales.sigma_v, w * scales.sigma_w

    def _second_order(self, z: list[float], dt: float, tau: float) -> float:
        """(1 + sqrt(3) tau s) / (1 + tau s)^2 times sqrt(tau): unit output variance."""
        n = max(1, math.ceil(10.0 * dt / tau))
        h = dt / n
        a = math.exp(-h / tau)
        for _ in range(n):
            # z1: white noise through 1/(1 + tau s), exactly; z2: z1 through it again (held)
            z2 = a * z[1] + (1.0 - a) * z[0]
            z[0] = a * z[0] + math.sqrt((1.0 - a * a) / (2.0 * tau)) * self._rng.gauss(0.0, 1.0)
            z[1] = z2
        return math.sqrt(tau) * (z[1] + math.sqrt(3.0) * (z[0] - z[1]))


@dataclass(frozen=True)
class AirflowParams:
    """Where the pad is above the ground (heights for the shear and turbulence are the
    vehicle's above the pad plus this) and whether there is turbulence."""

    pad_above_ground_m: float = 1.0  # the base's lid
    turbulence: bool = True


class Airflow:
    """The air the vehicle flies in: the mean wind (from the weather) sheared to its height,
    plus Dryden turbulence along and across it. Seeded; one per vehicle."""

    def __init__(self, params: AirflowParams | None = None, seed: int | None = None) -> None:
        self.params = params or AirflowParams()
        # its own stream: not the sequence of another part seeded with the same number
        self._dryden = Dryden(random.Random(None if seed is None else f"airflow/{seed}"))
        self.turbulence: tuple[float, float, float] = (0.0, 0.0, 0.0)  # u, v, w (m/s)

    def step(
        self,
        dt: float,
        wind20_ne: tuple[float, float],
        height_m: float,
        velocity_ne: tuple[float, float] = (0.0, 0.0),
    ) -> tuple[float, float, float]:
        """The air's velocity (north, east, down; m/s) at a vehicle `height_m` above the pad
        moving at `velocity_ne`, when the wind 20 ft above the ground is `wind20_ne`."""
        h = max(height_m, 0.0) + self.params.pad_above_ground_m
        w20 = math.hypot(*wind20_ne)
        k = shear(h)
        n, e = wind20_ne[0] * k, wind20_ne[1] * k
        if not self.params.turbulence or w20 == 0.0 or dt <= 0.0:
            return n, e, 0.0
        airspeed = math.hypot(velocity_ne[0] - n, velocity_ne[1] - e)
        u, v, w = self._dryden.step(dt, dryden_scales(h, w20), max(airspeed, w20 * k))
        self.turbulence = (u, v, w)
        cn, ce = wind20_ne[0] / w20, wind20_ne[1] / w20  # along the mean wind, and across it
        return n + u * cn - v * ce, e + u * ce + v * cn, w
