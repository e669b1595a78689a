"""Schedule timing: next due times for each kind (with time zones) and the missed-run policy."""

from __future__ import annotations

from datetime import UTC, datetime, timedelta

import pytest

from server.schedules.timing import TimingError, decide, next_after

T0 = datetime(2026, 3, 28, 23, 0, tzinfo=UTC)


def test_once():
    assert next_after("once", T0, at=T0 + timedelta(hours=1)) == T0 + timedelta(hours=1)
    assert next_after("once", T0, at=T0 - timedelta(hours=1)) is None


def test_interval_keeps_its_phase():
    anchor = T0 - timedelta(seconds=250)
    assert next_after("interval", T0, interval_s=100, anchor=anchor) == T0 + timedelta(seconds=50)


def test_cron_follows_the_time_zone_across_a_dst_change():
    # 06:00 every day in Lisbon: UTC+0 before 29 March 2026, UTC+1 after
    first = next_after("cron", T0, cron="0 6 * * *", tz="Europe/Lisbon")
    second = next_after("cron", first, cron="0 6 * * *", tz="Europe/Lisbon")
    assert first == datetime(2026, 3, 29, 5, 0, tzinfo=UTC)
    assert second == datetime(2026, 3, 30, 5, 0, tzinfo=UTC)
    before = next_after(
        "cron", datetime(2026, 3, 20, tzinfo=UTC), cron="0 6 * * *", tz="Europe/Lisbon"
    )
    assert before == datetime(2026, 3, 20, 6, 0, tzinfo=UTC)


def test_invalid_timing_is_refused():
    for kw in ({"cron": "61 * * * *"}, {"cron": "* * *"}):
        with pytest.raises(TimingError):
            next_after("cron", T0, **kw)
    with pytest.raises(TimingError):
        next_after("cron", T0, cron="0 6 * * *", tz="Mars/Olympus")


def test_missed_policy():
    due = T0
    assert decide(due, due + timedelta(seconds=5), "skip", 60).fire
    skipped = decide(due, due + timedelta(hours=2), "skip", 60)
    assert not skipped.fire and skipped.missed and "skipped" in skipped.note
    once = decide(due, due + timedelta(hours=2), "run_once", 60)
    assert once.fire and once.missed
