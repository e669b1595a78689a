"""When a schedule is next due, and what to do with due times missed while the server was down (pure)."""

from __future__ import annotations

from dataclasses import dataclass
from datetime import UTC, datetime, timedelta
from zoneinfo import ZoneInfo, ZoneInfoNotFoundError

from croniter import CroniterError, croniter


class TimingError(ValueError):
    """A schedule's timing is invalid; the message says why."""


def zone(name: str) -> ZoneInfo:
    """A time zone by IANA name."""
    try:
        return ZoneInfo(name)
    except (ZoneInfoNotFoundError, ValueError) as err:
        raise TimingError(f"unknown time zone {name!r}") from err


def check_cron(expr: str) -> None:
    """Raise TimingError unless `expr` is a 5-field cron expression that fires at some time."""
    if len(expr.split()) != 5 or not croniter.is_valid(expr):
        raise TimingError(f"not a 5-field cron expression: {expr!r}")
    _next_cron(expr, datetime(2000, 1, 1, tzinfo=UTC))


def _next_cron(expr: str, after: datetime) -> datetime:
    """The first time `expr` matches after `after`; TimingError for a date that never comes."""
    try:
        nxt: datetime = croniter(expr, after).get_next(datetime)
    except (CroniterError, ValueError, OverflowError) as err:
        # e.g. "0 0 31 2 *": every field is valid, but February has no 31st
        raise TimingError(
            f"cron expression {expr!r} never fires: no date matches all its fields"
        ) from err
    return nxt


def next_after(
    kind: str,
    after: datetime,
    *,
    at: datetime | None = None,
    interval_s: int | None = None,
    cron: str | None = None,
    tz: str = "UTC",
    anchor: datetime | None = None,
) -> datetime | None:
    """The first due time strictly after `after` (UTC, aware); None when there is none (a spent one-shot)."""
    if kind == "once":
        return at if at is not None and at > after else None
    if kind == "interval":
        if not interval_s or interval_s <= 0:
            raise TimingError("interval_s must be positive")
        start = anchor or after
        if start > after:
            return start
        periods = int((after - start).total_seconds() // interval_s) + 1
        return start + timedelta(seconds=periods * interval_s)
    if kind == "cron":
        if not cron:
            raise TimingError("a cron schedule needs a cron expression")
        check_cron(cron)
        return _next_cron(cron, after.astimezone(zone(tz))).astimezone(after.tzinfo)
    raise TimingError(f"unknown schedule kind {kind!r}")


@dataclass(frozen=True)
class Firing:
    """What the scheduler does now with a due schedule."""

    fire: bool
    scheduled_for: datetime
    missed: bool
    note: str


def decide(due: datetime, now: datetime, policy: str, grace_s: float) -> Firing:
    """Fire a due time on time; a time missed by more than `grace_s` follows the missed-run policy."""
    late = (now - due).total_seconds()
    if late <= grace_s:
        return Firing(True, due, False, "on time")
    if policy == "run_once":
        return Firing(
            True,
            due,
            True,
            f"missed by {late:.0f} s while the server was down; run once now (policy run_once)",
        )
    return Firing(
        False, due, True, f"missed by {late:.0f} s while the server was down; skipped (policy skip)"
    )
