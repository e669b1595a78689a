"""Telling an autopilot's reboot from its messages read late, by their `time_boot_ms`.

While the autopilot runs, its uptime (`time_boot_ms` of SYSTEM_TIME, ATTITUDE,
GLOBAL_POSITION_INT) grows with the arrival time at its clock's rate: the wall's on a flight
controller, the simulation's on a SITL (`--speedup` times the wall's; slower when the machine is
too busy for real time). A reboot shows in two ways:

- the uptime goes back (`UPTIME_BACK_MS`): the new boot counts from zero. Messages read late
  never do this: a link keeps their order. This is nearly every reboot, seen at once;
- the uptime falls short of what the arrival time says it should be (the last message on time,
  plus the time since at the clock's rate) by at least the uptime last seen — the old boot lasted
  that long before the new one began — and stays short for `HOLD_S` of arrivals: a reboot whose
  uptime had not gone back (a link outage longer than the uptime it had, or a reboot within
  seconds of starting).

Two things make the uptime fall short without a reboot, by less than the uptime:

- a backlog — the agent stopped for seconds, a telemetry radio's buffer — for the messages that
  waited; the messages on time after them are not short. Judged on the boot instant at the first
  late message, a companion stopped 1.2 s every 3 s saw the autopilot "reboot" seven times in
  its return and landing (a notification for the operator each time);
- a SITL's clock falling behind: the simulation's time, which a starved process loses for good
  (`sync_frame_time` catches up 0.1 s at most); from then on the uptime runs on from there.

And one thing makes it go back without a reboot: `time_boot_ms` is a uint32 of milliseconds
(ArduPilot's `AP_HAL::millis()`, PX4's boot time cast down), so it wraps to zero after 49.7 days
of uptime — a drone left powered on its charging base reaches that. Counted on past the wrap
(`WRAP_MS`), the uptime is on time, where a new boot's is ahead of the time since; the second
rule's bound is the uptime since the wrap, which a reboot's shortfall still exceeds.
"""

from __future__ import annotations

from collections import deque
from itertools import pairwise
from statistics import median

SHORT_S = 1.0  # the least shortfall (the clock's seconds) that may be a reboot
HOLD_S = 0.5  # arrival seconds it must stay short (a backlog is read in milliseconds)
# time_boot_ms this much below the highest seen: a reboot at once. An autopilot stamps its
# messages from one clock as it sends them (PX4 with the sample's time: some ms older); a new boot
# mostly speaks with seconds less uptime than the old had (not always: the simulator at 20x,
# rebooted at 20.2 s of uptime, spoke again at 20.7 s, which the second rule tells)
UPTIME_BACK_MS = 200
RATE_WINDOW_S = 10.0  # arrival seconds of messages on time the clock's rate is taken over
RATE_MIN_SPAN_S = 1.0  # until they span this long the rate is taken as the wall's
RATE_STEP_S = 0.1  # the rate is the median over steps of at least this many arrival seconds
WRAP_MS = 1 << 32  # time_boot_ms wraps to zero after this many milliseconds (49.7 days)


class BootWatch:
    """One autopilot's boot, from the `time_boot_ms` of its messages as they arrive."""

    def __init__(self) -> None:
        self.uptime_ms: int | None = None  # the highest time_boot_ms of this boot, unwrapped
        self._last = (0.0, 0)  # (arrival, uptime ms) of the last message on time
        # messages on time at least RATE_STEP_S apart, over RATE_WINDOW_S: the clock's rate
        self._steps: deque[tuple[float, int]] = deque()
        self._rate: float | None = None  # the rate over _steps, until they change
        self._short_since: float | None = None  # first arrival of a shortfall that may be one

    @property
    def rate(self) -> float:
        """The autopilot's clock seconds per arrival second while it runs: the median over the
        steps between messages on time. A mean over the window would count the time a starved
        SITL lost (0.5 s of a 1.3 s window starved: 13.8x for a 20x clock) and take the next boot's
        uptime, more than the old one had, for the old boot's, on time at that rate."""
        s = self._steps
        if not s or s[-1][0] - s[0][0] < RATE_MIN_SPAN_S:
            return 1.0
        if self._rate is None:
            self._rate = max(
                median((b[1] - a[1]) / 1000 / (b[0] - a[0]) for a, b in pairwise(s)), 1e-3
            )
        return self._rate

    def check(self, boot_ms: int, now: float) -> str | None:
        """Feed one message's `time_boot_ms`, arrived at `now`: why it is a reboot, or None."""
        uptime = self.uptime_ms
        if uptime is None:
            self._restart(boot_ms, now)  # the first message
            return None
        raw, boot_ms = boot_ms, boot_ms + uptime - uptime % WRAP_MS  # the wraps seen, added
        if boot_ms < uptime - UPTIME_BACK_MS:
            if self._shortfall(boot_ms + WRAP_MS, now) <= -SHORT_S:
                self._restart(raw, now)  # a new boot: ahead of the time since, counted on
                return f"its uptime went back from {uptime / 1000:.1f} s to {raw / 1000:.1f} s"
            boot_ms += WRAP_MS  # the uint32 wrapped: the uptime goes on
        short = self._shortfall(boot_ms, now)
        # a reboot's shortfall is at least the uptime last seen as the clock counted it: since
        # the wrap, where there was one (the unwrapped one would hide reboots after it)
        if short < max(SHORT_S, (uptime % WRAP_MS - UPTIME_BACK_MS) / 1000):
            self._short_since = None  # on time, read late, or a clock that fell behind
            self.uptime_ms = max(uptime, boot_ms)
            self._on_time(boot_ms, now)
            return None
        if self._short_since is None:
            self._short_since = now
        if now - self._short_since < HOLD_S:
            return None
        self._restart(raw, now)
        return f"its uptime {short:.1f} s short of the time since it last spoke"

    def _shortfall(self, boot_ms: int, now: float) -> float:
        """Seconds of its clock `boot_ms` falls short of the last message on time plus the time
        since at the clock's rate: a little for a message read late, below zero when ahead."""
        last_t, last_ms = self._last
        return (now - last_t) * self.rate - (boot_ms - last_ms) / 1000

    def _on_time(self, boot_ms: int, now: float) -> None:
        self._last = (now, boot_ms)
        steps = self._steps
        if steps and now - steps[-1][0] < RATE_STEP_S:
            return
        steps.append(self._last)
        while now - steps[0][0] > RATE_WINDOW_S:
            steps.popleft()
        self._rate = None

    def _restart(self, boot_ms: int, now: float) -> None:
        self.uptime_ms, self._short_since = boot_ms, None
        self._steps.clear()
        self._on_time(boot_ms, now)
