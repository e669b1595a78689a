"""Telling an autopilot's reboot from its messages read late, by their `time_boot_ms`.

While the autopilot runs, its boot instant — a message's arrival time minus its `time_boot_ms`
(SYSTEM_TIME, ATTITUDE, GLOBAL_POSITION_INT) — stays put. A reboot shows in two ways:

- the uptime goes back (`UPTIME_BACK_MS`): the new boot counts from zero. Messages read late
  never do this: a link keeps their order. This is nearly every reboot, seen at once;
- the boot instant moves more than `SHIFT_S` later and stays there for `HOLD_S` of arrivals: a
  reboot its link did not see (the uptime had not gone back: a link outage longer than the uptime
  it had, or a reboot within a second of starting).

A backlog — the agent stopped for seconds, a telemetry radio's buffer — also moves the boot
instant later, but only for the messages that waited: once it is read, the messages on time show
the old instant again. Judged at the first late message, a companion stopped 1.2 s every 3 s saw
the autopilot "reboot" seven times in its return and landing (a notification for the operator
each time).
"""

from __future__ import annotations

SHIFT_S = 1.0  # the boot instant this much later: a reboot, if it stays
HOLD_S = 0.5  # arrival seconds it must stay later (a backlog is read in milliseconds)
# time_boot_ms this much below the highest seen: a reboot at once. An autopilot stamps its
# messages from one clock as it sends them (PX4 with the sample's time: some ms older); a new boot
# mostly speaks with seconds less uptime than the old had (not always: the simulator rebooted at
# 1.0 s of uptime spoke again at 0.99 s, which the second rule tells)
UPTIME_BACK_MS = 200


class BootWatch:
    """One autopilot's boot instant, from the `time_boot_ms` of its messages as they arrive."""

    def __init__(self) -> None:
        self.booted_at: float | None = None  # arrival clock of the boot (least delayed)
        self._uptime_ms: int | None = None  # the highest time_boot_ms of this boot
        self._later_since: float | None = None  # first arrival showing a later instant

    def check(self, boot_ms: int, now: float) -> str | None:
        """Feed one message's `time_boot_ms`, arrived at `now`: why it is a reboot, or None."""
        booted = now - boot_ms / 1000.0
        last, uptime = self.booted_at, self._uptime_ms
        if last is None or uptime is None:
            self.booted_at, self._uptime_ms = booted, boot_ms
            return None
        if boot_ms < uptime - UPTIME_BACK_MS:
            return self._rebooted(
                booted, boot_ms, f"its uptime went back from {uptime / 1000:.1f} s to "
                f"{boot_ms / 1000:.1f} s"
            )  # fmt: skip
        self._uptime_ms = max(uptime, boot_ms)
        shift = booted - last
        if shift <= SHIFT_S:
            self._later_since = None  # on time (again): a later instant seen was a backlog
            self.booted_at = min(booted, last + 0.001)  # the least delayed; clocks drift
            return None
        if self._later_since is None:
            self._later_since = now
        if now - self._later_since < HOLD_S:
            return None
        return self._rebooted(booted, boot_ms, f"its boot moved {shift:.1f} s later")

    def _rebooted(self, booted: float, boot_ms: int, why: str) -> str:
        self.booted_at, self._uptime_ms, self._later_since = booted, boot_ms, None
        return why
