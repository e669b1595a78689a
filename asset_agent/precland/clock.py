"""The sensors' clock as the agent sees it, followed from the capture timestamps it receives.

Frames and IR readings carry capture timestamps on the sensors' clock (in the simulator, the world
clock). `SensorClock` fits that clock's offset and rate against the agent's monotonic clock, so
fusion, the Kalman filter and the control step all run in sensor-clock seconds.

A sensor's clock may restart (a camera or IR sensor that reboots counts from 0 again; the
simulated world restarted under a running agent): its timestamps jump back, and read on the old
time base every reading would look minutes old and be dropped as stale. A jump back in a source's
own timestamps (they never go back otherwise) is a new epoch of that source: its timestamps are
carried onto the agent's time base from there by a per-source shift, the new epoch's first
reading taken as captured now. So the time base everything downstream holds (fusion's readings,
the filter's last update, the vehicle's track, the landing's timers) stays continuous and nothing
has to be reset. A jump forward beyond what the fit predicts is a new epoch too. A late reading
of the previous epoch (in flight when the clock restarted) still maps by that epoch's shift.
"""

from __future__ import annotations

import asyncio
import logging
import math
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass

log = logging.getLogger(__name__)


@dataclass
class _Epoch:
    """One source's time base: sensor timestamp + shift = agent sensor-clock time."""

    shift: float = 0.0
    last_ts: float = -math.inf  # the newest raw timestamp of this epoch
    last_w: float = 0.0  # when it arrived (wall)
    previous_shift: float | None = None  # the epoch before, for its late readings
    previous_last_ts: float = -math.inf  # the newest raw timestamp of the epoch before
    carried_at: float | None = None  # when (wall) the shift was set at a jump


class SensorClock:
    """The sensors' clock as seen from here: rate and offset against `wall` from received stamps.

    now() = rate * wall + offset, with the rate fitted over the last `window_s` wall seconds through
    the least-delayed readings (or fixed) and the offset the largest seen (the least-delayed
    sample); never goes backwards.
    `observe` maps each source's timestamps onto that clock across the source's restarts
    (`epoch_jump_s`: how far a source's timestamp may step back before it is a new epoch;
    `epoch_ahead_s`: how far ahead of what the wall time since its last reading explains;
    `first_behind_s`: how far behind the others' a source's first timestamp must be to be on
    another epoch; a new epoch's shift follows its least-delayed reading for `settle_s` wall
    seconds).
    """

    def __init__(
        self,
        rate: float | None = None,
        window_s: float = 2.0,
        wall: Callable[[], float] = time.monotonic,
        epoch_jump_s: float = 1.0,
        epoch_ahead_s: float = 30.0,
        settle_s: float = 2.0,
        first_behind_s: float = 10.0,
        min_span_s: float = 0.3,
    ) -> None:
        self.fixed_rate = rate
        self.window_s = window_s
        self.wall = wall
        self.epoch_jump_s = epoch_jump_s
        self.epoch_ahead_s = epoch_ahead_s
        self.settle_s = settle_s
        self.first_behind_s = first_behind_s
        self.min_span_s = min_span_s
        self.epochs = 0  # new epochs seen, over every source
        self._samples: deque[tuple[float, float, str]] = deque()
        self._sources: dict[str, _Epoch] = {}
        self._last = -math.inf
        self._rate = 1.0  # fitted (_refit) unless fixed
        self._fitted_at = -math.inf

    @property
    def ready(self) -> bool:
        """True once a timestamp has been seen."""
        return bool(self._samples)

    @property
    def rate(self) -> float:
        """Sensor seconds per wall second."""
        return self.fixed_rate if self.fixed_rate is not None else self._rate

    def _refit(self, w: float) -> None:
        """The rate from the least-delayed reading of each half of the window, `min_span_s` wall
        seconds apart at least, else the rate so far. Readings that queued behind a stalled loop
        arrive in a burst, each later than the one before by more than its own interval: a fit
        through them (a least-squares slope of a burst a few milliseconds long) once read 1000x
        and carried the clock 10 s ahead of its sensors, where every reading was stale."""
        s = self._samples
        if self.fixed_rate is not None or len(s) < 3 or w - self._fitted_at < 0.05:
            return
        self._fitted_at = w
        mid, r = (s[0][0] + s[-1][0]) / 2, self._rate
        early = max((x for x in s if x[0] <= mid), key=lambda x: x[1] - r * x[0], default=None)
        late = max((x for x in s if x[0] > mid), key=lambda x: x[1] - r * x[0], default=None)
        if early is None or late is None or late[0] - early[0] < self.min_span_s:
            return
        slope = (late[1] - early[1]) / (late[0] - early[0])
        if slope > 0:
            self._rate = slope

    def observe(self, ts: float, source: str = "sensor") -> float:
        """A capture timestamp of `source` just received; returns it on this clock's time base."""
        epoch = self._sources.setdefault(source, _Epoch())
        w = self.wall()
        t = self._map(epoch, ts, source, w)
        self._samples.append((w, t, source))
        while self._samples and w - self._samples[0][0] > self.window_s:
            self._samples.popleft()
        self._refit(w)
        return t

    def _map(self, epoch: _Epoch, ts: float, source: str, w: float) -> float:
        if not self._samples:  # the first timestamp: the time base starts here
            epoch.last_ts, epoch.last_w = ts, w
            return ts + epoch.shift
        predicted, rate = self._predict(), self.rate
        # a source's first timestamp may be on another clock than the others' (its own sensor
        # restarted before it was first seen); a first reading merely late (a camera's first
        # frame, slow to render on a loaded machine) is on theirs: taken for an epoch, it would
        # be read as captured now, ahead of every other source
        seen = epoch.last_ts != -math.inf
        back = ts < epoch.last_ts - self.epoch_jump_s or (
            not seen and ts < predicted - self.first_behind_s
        )
        # ahead by far more than the wall time since its last reading explains (not a burst of
        # readings queued behind a stalled loop: each is a little after the one before)
        ahead = seen and ts - epoch.last_ts > rate * (w - epoch.last_w) + self.epoch_ahead_s
        if not (back or ahead):
            if ts > epoch.last_ts:
                epoch.last_ts, epoch.last_w = ts, w
            settling = epoch.carried_at is not None and w - epoch.carried_at <= self.settle_s
            if settling and any(s != source for _, _, s in self._samples):
                # the first reading of the epoch may have come late: its shift follows the
                # least-delayed reading since, against the other sources' fit (else one late
                # first frame would carry every later one ahead of the others)
                epoch.shift = min(epoch.shift, self._predict(exclude=source) - ts)
            return ts + epoch.shift
        old, carried = epoch.previous_shift, epoch.carried_at
        # a reading in flight when the sensor restarted continues the previous epoch's count
        if old is not None and carried is not None and w - carried <= self.settle_s:
            if abs(ts - epoch.previous_last_ts) <= self.epoch_jump_s + rate * (w - carried):
                return ts + old
        epoch.previous_shift, epoch.shift = epoch.shift, predicted - ts
        epoch.previous_last_ts = epoch.last_ts
        epoch.last_ts, epoch.last_w, epoch.carried_at = ts, w, w
        self.epochs += 1
        log.warning(
            "precland: the %s clock restarted (timestamp %.3f s after %.3f s): a new epoch, "
            "carried on from %.3f s",
            source,
            ts,
            predicted - epoch.previous_shift,
            predicted,
        )
        return predicted

    def _predict(self, exclude: str | None = None) -> float:
        r = self.rate
        offset = max(t - r * w for w, t, s in self._samples if s != exclude)
        now = r * self.wall() + offset
        return now if exclude is not None else max(self._last, now)

    def now(self) -> float:
        """Current sensor-clock time (0.0 before any timestamp)."""
        if not self._samples:
            return 0.0
        self._last = self._predict()
        return self._last

    async def sleep(self, seconds: float) -> None:
        """Sleep this many sensor-clock seconds."""
        await asyncio.sleep(max(0.0, seconds) / self.rate)
