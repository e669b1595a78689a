"""Fusion of any set of sources with freshness windows and weights — the thesis's truth table.

At each step:
- two or more sources gave a *new* value (arrived since the previous step and younger than the
  source's freshness window): their weighted average (headings averaged on the circle, over the
  sources that have one);
- exactly one did: that value;
- none did: the last output while it is younger than `hold_s` (1 s), marked "held";
- otherwise: no target (None).

A fused value's 1-sigma is that of the weighted average of independent readings,
sqrt(sum(w² sigma²)) / sum(w), when every reading reports one (else None: the filter's model).
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass
from typing import Literal

from asset_agent.precland.config import FusionConfig
from asset_agent.precland.measure import Measurement

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class FusedTarget:
    """The fused pad position relative to the vehicle (NED), its heading, how it was made, and
    its 1-sigma per axis (m, None when a reading reported none)."""

    t: float
    rel_ned: tuple[float, float, float]
    heading: float | None
    sources: tuple[str, ...]
    kind: Literal["fused", "single", "held"]
    sigma_m: float | None = None


class Fusion:
    """Holds the newest reading per source and applies the truth table on each `step`."""

    def __init__(self, config: FusionConfig | None = None) -> None:
        self.config = config or FusionConfig()
        self._pending: dict[str, Measurement] = {}
        self._last: FusedTarget | None = None

    def submit(self, m: Measurement) -> None:
        """Offer a reading; unknown sources are logged and ignored."""
        if m.source not in self.config.sources:
            log.debug("fusion ignores source %s", m.source)
            return
        self._pending[m.source] = m

    def step(self, now: float) -> FusedTarget | None:
        """Apply the truth table at time `now`; consumes the pending readings."""
        fresh = [
            m
            for s, m in self._pending.items()
            if 0.0 <= now - m.t <= self.config.sources[s].freshness_s
        ]
        self._pending.clear()
        if len(fresh) >= 2:
            self._last = self._average(fresh)
            return self._last
        if len(fresh) == 1:
            m = fresh[0]
            self._last = FusedTarget(m.t, m.rel_ned, m.heading, (m.source,), "single", m.sigma_m)
            return self._last
        if self._last is not None and now - self._last.t < self.config.hold_s:
            last = self._last
            return FusedTarget(
                last.t, last.rel_ned, last.heading, last.sources, "held", last.sigma_m
            )
        return None

    def _average(self, ms: list[Measurement]) -> FusedTarget:
        weights = [self.config.sources[m.source].weight for m in ms]
        total = sum(weights)
        rel = tuple(
            sum(w * m.rel_ned[i] for w, m in zip(weights, ms, strict=True)) / total
            for i in range(3)
        )
        hs = [(w, m.heading) for w, m in zip(weights, ms, strict=True) if m.heading is not None]
        heading = None
        if hs:
            heading = math.atan2(
                sum(w * math.sin(h) for w, h in hs), sum(w * math.cos(h) for w, h in hs)
            )
        sigmas = [m.sigma_m for m in ms]
        sigma = None
        if all(s is not None for s in sigmas):
            var = sum(w * w * s * s for w, s in zip(weights, sigmas, strict=True) if s is not None)
            sigma = math.sqrt(var) / total
        t = max(m.t for m in ms)
        sources = tuple(sorted(m.source for m in ms))
        return FusedTarget(t, (rel[0], rel[1], rel[2]), heading, sources, "fused", sigma)
