"""Time helpers: everything in the server is an aware UTC datetime, and every time in a REST body
is RFC 3339 in UTC with `Z` (`rfc3339`; epoch milliseconds only in socket envelopes)."""

from __future__ import annotations

from datetime import UTC, datetime


def utcnow() -> datetime:
    """The current time, aware, in UTC."""
    return datetime.now(UTC)


def rfc3339(dt: datetime) -> str:
    """`2026-11-22T05:00:00Z` (microseconds when there are any): RFC 3339, UTC, `Z`.
    A naive datetime is taken as UTC (the server's naive times are UTC: SQLite keeps no zone)."""
    if dt.tzinfo is None:
        dt = dt.replace(tzinfo=UTC)
    text = dt.astimezone(UTC).isoformat()
    return text.removesuffix("+00:00") + "Z"


def to_ms(dt: datetime) -> int:
    """Unix milliseconds of an aware datetime."""
    return int(dt.timestamp() * 1000)
