"""A deterministic, seedable model of the satellites a static GNSS base receiver tracks.

Not an orbit propagator: each satellite's range oscillates around a plausible mean with its
constellation's orbital period, which keeps pseudoranges, carrier phases, range rates and
signal strengths realistic and bounded forever, and reproducible from (seed, time).
"""

from __future__ import annotations

import math
import random
from dataclasses import dataclass

SPEED_OF_LIGHT = 299_792_458.0  # m/s
WGS84_A = 6_378_137.0
WGS84_F = 1 / 298.257223563
GPS_WEEK_MS = 7 * 24 * 3600 * 1000


def geodetic_to_ecef(lat_deg: float, lon_deg: float, height_m: float) -> tuple[float, float, float]:
    """WGS84 latitude/longitude (degrees) and ellipsoidal height (m) to ECEF metres."""
    e2 = WGS84_F * (2 - WGS84_F)
    lat, lon = math.radians(lat_deg), math.radians(lon_deg)
    n = WGS84_A / math.sqrt(1 - e2 * math.sin(lat) ** 2)
    x = (n + height_m) * math.cos(lat) * math.cos(lon)
    y = (n + height_m) * math.cos(lat) * math.sin(lon)
    z = (n * (1 - e2) + height_m) * math.sin(lat)
    return x, y, z


@dataclass(frozen=True)
class Signal:
    """One tracked signal: its RTCM MSM signal-mask id, RINEX code and carrier frequency."""

    rtcm_id: int
    code: str
    frequency_hz: float

    @property
    def wavelength_m(self) -> float:
        """Carrier wavelength in metres."""
        return SPEED_OF_LIGHT / self.frequency_hz


@dataclass(frozen=True)
class Constellation:
    """A GNSS: its name, the MSM message base number, PRNs, signals and orbital period."""

    name: str
    msm_base: int
    prns: tuple[int, ...]
    signals: tuple[Signal, ...]
    period_s: float
    mean_range_m: float


GPS = Constellation(
    name="GPS",
    msm_base=1070,
    prns=tuple(range(1, 33)),
    signals=(Signal(2, "1C", 1575.42e6), Signal(16, "2L", 1227.60e6)),
    period_s=43_082.0,
    mean_range_m=23_000_000.0,
)
GALILEO = Constellation(
    name="GALILEO",
    msm_base=1090,
    prns=tuple(range(1, 37)),
    signals=(Signal(2, "1C", 1575.42e6), Signal(15, "7Q", 1207.14e6)),
    period_s=50_680.0,
    mean_range_m=26_000_000.0,
)


@dataclass(frozen=True)
class SignalObservation:
    """One signal of one satellite at one epoch."""

    signal: Signal
    pseudorange_m: float
    phase_range_m: float
    phase_range_rate_mps: float
    cnr_dbhz: float
    lock_time_ms: int


@dataclass(frozen=True)
class SatelliteObservation:
    """One satellite at one epoch: its geometric range, range rate and signals."""

    prn: int
    range_m: float
    range_rate_mps: float
    signals: tuple[SignalObservation, ...]


@dataclass(frozen=True)
class _Track:
    prn: int
    amplitude_m: float
    phase_rad: float
    iono_l1_m: float
    cnr_base: float
    ambiguities: tuple[int, ...]


class Sky:
    """The satellites one constellation shows the base: fixed set, deterministic observables."""

    def __init__(self, constellation: Constellation, seed: int, count: int) -> None:
        if not 1 <= count <= len(constellation.prns):
            raise ValueError(
                f"{constellation.name}: satellite count must be 1..{len(constellation.prns)}"
            )
        self.constellation = constellation
        self._seed = seed
        rng = random.Random(f"sky:{seed}:{constellation.name}")
        prns = sorted(rng.sample(constellation.prns, count))
        self._tracks = tuple(
            _Track(
                prn=prn,
                amplitude_m=rng.uniform(1.5e6, 3.0e6),
                phase_rad=rng.uniform(0, 2 * math.pi),
                iono_l1_m=rng.uniform(1.5, 9.0),
                cnr_base=rng.uniform(36.0, 48.0),
                ambiguities=tuple(rng.randint(-150, 150) for _ in constellation.signals),
            )
            for prn in prns
        )

    @property
    def prns(self) -> tuple[int, ...]:
        """PRNs of the tracked satellites, ascending."""
        return tuple(t.prn for t in self._tracks)

    def observe(self, t_s: float, lock_time_ms: int) -> tuple[SatelliteObservation, ...]:
        """Every tracked satellite's observables at simulated time `t_s` (seconds)."""
        c = self.constellation
        omega = 2 * math.pi / c.period_s
        # a wandering receiver clock, as a range offset common to every satellite
        clock_arg = 2 * math.pi * t_s / 3600.0
        clock_m = 50.0 * math.sin(clock_arg)
        clock_rate = 50.0 * 2 * math.pi / 3600.0 * math.cos(clock_arg)
        out = []
        for track in self._tracks:
            arg = omega * t_s + track.phase_rad
            rng_m = c.mean_range_m + track.amplitude_m * math.sin(arg)
            rate = track.amplitude_m * omega * math.cos(arg)
            # shorter range ~ higher elevation ~ stronger signal and less ionosphere
            closeness = (c.mean_range_m - rng_m) / track.amplitude_m  # -1 .. 1
            noise = random.Random(f"obs:{self._seed}:{c.name}:{track.prn}:{t_s:.3f}")
            signals = []
            l1 = c.signals[0].frequency_hz
            for sig, amb in zip(c.signals, track.ambiguities, strict=True):
                iono = track.iono_l1_m * (1.2 - 0.4 * closeness) * (l1 / sig.frequency_hz) ** 2
                base = rng_m + clock_m
                signals.append(
                    SignalObservation(
                        signal=sig,
                        pseudorange_m=base + iono + noise.gauss(0.0, 0.3),
                        phase_range_m=base
                        - iono
                        + amb * sig.wavelength_m
                        + noise.gauss(0.0, 0.002),
                        phase_range_rate_mps=rate + clock_rate + noise.gauss(0.0, 0.01),
                        cnr_dbhz=round(track.cnr_base + 4 * closeness + noise.uniform(-1, 1), 2),
                        lock_time_ms=lock_time_ms,
                    )
                )
            out.append(
                SatelliteObservation(
                    prn=track.prn,
                    range_m=rng_m + clock_m,
                    range_rate_mps=rate + clock_rate,
                    signals=tuple(signals),
                )
            )
        return tuple(out)
