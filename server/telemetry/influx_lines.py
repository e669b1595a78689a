"""InfluxDB basics shared by both query dialects: time conversions, line protocol, the version probe.

Layout: measurement `telemetry`, tag `asset_id`, one field per flat sample field plus the integer
field `seq`, timestamp in nanoseconds. Numbers other than `seq` are stored as floats so a field
never changes type between samples (InfluxDB refuses a type change within a shard).
"""

from __future__ import annotations

import logging
from datetime import UTC, datetime, timedelta

from influxdb_client import Point, WritePrecision

from server.kit import time as kit_time
from server.telemetry.store import Query, Sample

log = logging.getLogger(__name__)

MEASUREMENT = "telemetry"
EPOCH = datetime(1970, 1, 1, tzinfo=UTC)
NS_MIN, NS_MAX = -9_223_372_036_854_775_806, 9_223_372_036_854_775_806  # InfluxDB's time range
RESERVED = frozenset({"time", "seq", "asset_id", "_time", "_field", "_value", "_measurement"})


class InfluxStoreError(RuntimeError):
    """InfluxDB refused or failed a request that may succeed when retried."""


def to_ns(ts: datetime) -> int:
    """An aware (or naive UTC) datetime -> integer nanoseconds since the epoch, exactly."""
    if ts.tzinfo is None:
        ts = ts.replace(tzinfo=UTC)
    return (ts - EPOCH) // timedelta(microseconds=1) * 1000


def clamp_ns(ts: datetime) -> int:
    """Nanoseconds since the epoch clamped into the range InfluxDB accepts in a query."""
    try:
        return max(NS_MIN, min(NS_MAX, to_ns(ts)))
    except OverflowError:
        return NS_MIN if ts.year < 1970 else NS_MAX


def iso_of_ns(ns: int) -> str:
    """Integer nanoseconds -> RFC 3339 UTC with `Z` (microsecond resolution, like our datetimes)."""
    return kit_time.rfc3339(EPOCH + timedelta(microseconds=ns // 1000))


def rfc3339(ns: int) -> str:
    """Integer nanoseconds -> an RFC 3339 literal with nanoseconds (Flux and the delete API)."""
    whole = EPOCH + timedelta(seconds=ns // 1_000_000_000)
    return whole.strftime("%Y-%m-%dT%H:%M:%S") + f".{ns % 1_000_000_000:09d}Z"


def to_line(sample: Sample) -> str | None:
    """One sample as a line-protocol line, or None when it cannot be stored (logged)."""
    ns = to_ns(sample.ts)
    if not NS_MIN <= ns <= NS_MAX:
        log.warning(
            "telemetry sample of %s at %s is outside InfluxDB's time range; dropped",
            sample.asset_id,
            sample.ts,
        )
        return None
    point = Point(MEASUREMENT).tag("asset_id", str(sample.asset_id)).time(ns, WritePrecision.NS)
    for name, value in sample.fields.items():
        if name in RESERVED or not name:
            log.warning("telemetry field %r is reserved in InfluxDB; dropped", name)
        elif isinstance(value, int) and not isinstance(value, bool):
            point.field(name, float(value))
        else:
            point.field(name, value)
    point.field("seq", int(sample.seq))
    return str(point.to_line_protocol())


def window_us(q: Query) -> tuple[int, int]:
    """Bucket width and offset in microseconds: buckets start at `q.start` + k * `q.every_s`."""
    every = max(1, round((q.every_s or 1) * 1_000_000))
    return every, (clamp_ns(q.start) // 1000) % every


def major_version(header: str | None) -> int:
    """The major version from X-Influxdb-Version ("1.6.7~rc0", "v2.7.1", "3.0.1"); 2 if unknown."""
    digits = (header or "").strip().lstrip("vV").split(".", 1)[0]
    return int(digits) if digits.isdigit() else 2
