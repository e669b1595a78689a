"""Time helpers: everything in the server is an aware UTC datetime."""

from __future__ import annotations

from datetime import UTC, datetime


def utcnow() -> datetime:
    """The current time, aware, in UTC."""
    return datetime.now(UTC)


def to_ms(dt: datetime) -> int:
    """Unix milliseconds of an aware datetime."""
    return int(dt.timestamp() * 1000)
