"""Fault injection per source (thesis ch. 5), settable at run time.

A reading is dropped when any configured fault says so:
- random: with probability r_drop;
- periodic: kept for p_keep seconds, then dropped for p_drop seconds, repeating from the moment
  the fault was set (the first reading when configured at start);
- "below X m" / "above X m": while the vehicle is below / above that height above the pad.
r_drop = p_keep = p_drop = 0 (and no heights) disables injection for that source.
"""

from __future__ import annotations

import logging

import numpy as np

from asset_agent.precland.config import FaultConfig

log = logging.getLogger(__name__)


class FaultInjector:
    """Decides, reading by reading, whether a source's value gets through."""

    def __init__(
        self, faults: dict[str, FaultConfig] | None = None, seed: int | None = None
    ) -> None:
        self._faults: dict[str, FaultConfig] = dict(faults or {})
        self._t0: dict[str, float | None] = dict.fromkeys(self._faults)
        self._rng = np.random.default_rng(seed)
        self.dropped: dict[str, int] = {}

    def set(self, source: str, config: FaultConfig, now: float | None = None) -> None:
        """Replace the fault of `source`; the periodic cycle starts at `now` (or the next reading)."""
        self._faults[source] = config
        self._t0[source] = now
        log.info("fault injection for %s set to %s", source, config.model_dump())

    def clear(self, source: str) -> None:
        """Remove any fault from `source`."""
        self._faults.pop(source, None)
        self._t0.pop(source, None)

    def get(self, source: str) -> FaultConfig:
        """The current fault of `source` (all-disabled when none)."""
        return self._faults.get(source, FaultConfig())

    def admit(self, source: str, t: float, height: float) -> bool:
        """True when the reading of `source` taken at `t` at `height` gets through."""
        cfg = self._faults.get(source)
        if cfg is None:
            return True
        drop = False
        if cfg.r_drop > 0 and self._rng.random() < cfg.r_drop:
            drop = True
        period = cfg.p_keep + cfg.p_drop
        if period > 0:
            t0 = self._t0.get(source)
            if t0 is None:
                t0 = self._t0[source] = t
            if (t - t0) % period >= cfg.p_keep:
                drop = True
        if cfg.fail_below_m is not None and height < cfg.fail_below_m:
            drop = True
        if cfg.fail_above_m is not None and height > cfg.fail_above_m:
            drop = True
        if drop:
            self.dropped[source] = self.dropped.get(source, 0) + 1
        return not drop
