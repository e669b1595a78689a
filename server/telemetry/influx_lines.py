"""InfluxDB basics shared by both query dialects: time conversions, line protocol, the version probe.

Layout: measurement `telemetry`, tag `asset_id`, one field per flat sample field plus the integer
field `seq`, timestamp in nanoseconds. Numbers other than `seq` are stored as floats so a field
never changes type between samples (InfluxDB refuses a type change within a shard).
"""

from __future__ import annotations

import gzip
import logging
import math
from collections.abc import Sequence
from datetime import UTC, datetime, timedelta
from typing import Any

from server.kit import time as kit_time
from server.telemetry.store import Query, Sample, flatten

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


_ESCAPE_MEASUREMENT = str.maketrans({",": r"\,", " ": r"\ ", "\n": r"\n", "\t": r"\t", "\r": r"\r"})
_ESCAPE_KEY = str.maketrans(
    {",": r"\,", "=": r"\=", " ": r"\ ", "\n": r"\n", "\t": r"\t", "\r": r"\r"}
)
_ESCAPE_STRING = str.maketrans({'"': r"\"", "\\": r"\\"})
_PREFIX = MEASUREMENT.translate(_ESCAPE_MEASUREMENT) + ",asset_id="


def _tag_value(text: str) -> str:
    value = text.translate(_ESCAPE_KEY)
    return value + " " if value.endswith("\\") else value


_KEYS: dict[str, str] = {}  # field name -> its escaped form: a fleet repeats a few dozen names
_KEYS_MAX = 4096  # names beyond these (a client inventing names) are escaped each time


def _key(name: str) -> str:
    key = _KEYS.get(name)
    if key is None:
        key = name.translate(_ESCAPE_KEY)
        if len(_KEYS) < _KEYS_MAX:
            _KEYS[name] = key
    return key


def _field(name: str, value: Any) -> str | None:
    """`name=value` in line protocol; None for a value InfluxDB cannot hold (not finite)."""
    key = _key(name)
    if isinstance(value, bool):
        return f"{key}={'true' if value else 'false'}"
    if isinstance(value, int | float):
        number = float(value)  # every number a float: a field never changes type
        if not math.isfinite(number):
            return None
        text = repr(number)
        return f"{key}={text[:-2] if text.endswith('.0') else text}"
    if isinstance(value, str):
        return f'{key}="{str(value).translate(_ESCAPE_STRING)}"'
    return None


def to_line(sample: Sample) -> str | None:
    """One sample as a line-protocol line (the flat form of its payload, fields sorted as
    influxdb-client sorts them), or None when it cannot be stored (logged)."""
    ns = to_ns(sample.ts)
    if not NS_MIN <= ns <= NS_MAX:
        log.warning(
            "telemetry sample of %s at %s is outside InfluxDB's time range; dropped",
            sample.asset_id,
            sample.ts,
        )
        return None
    fields = [("seq", f"seq={int(sample.seq)}i")]
    for name, value in flatten(sample.data()).items():
        if name == "asset_id":
            continue  # the payload names its asset: that is the point's tag
        if name in RESERVED or not name:
            log.warning("telemetry field %r is reserved in InfluxDB; dropped", name)
            continue
        encoded = _field(name, value)
        if encoded is not None:
            fields.append((name, encoded))
    fields.sort()
    body = ",".join(text for _, text in fields)
    return f"{_PREFIX}{_tag_value(str(sample.asset_id))} {body} {ns}"


def encode_batch(samples: Sequence[Sample], chunk: int, gzipped: bool) -> list[bytes | list[str]]:
    """A batch as line protocol in chunks of `chunk` lines: gzip-compressed bodies (InfluxDB 1.x's
    /write) or lists of lines (influxdb-client's v2 write). CPU work alone (~37 us a sample), run
    in a worker thread so that a 2,000-sample batch does not hold the server's event loop."""
    lines = [line for line in map(to_line, samples) if line is not None]
    chunks = [lines[i : i + chunk] for i in range(0, len(lines), chunk)]
    if not gzipped:
        return list(chunks)
    # ~8x smaller, cheap at level 1
    return [gzip.compress("\n".join(c).encode(), compresslevel=1) for c in chunks]


def window_us(q: Query) -> tuple[int, int]:
    """Bucket width and offset in microseconds: buckets start at `q.start` + k * `q.every_s`."""
    every = max(1, round((q.every_s or 1) * 1_000_000))
    return every, (clamp_ns(q.start) // 1000) % every


def major_version(header: str | None) -> int:
    """The major version from X-Influxdb-Version ("1.6.7~rc0", "v2.7.1", "3.0.1"); 2 if unknown."""
    digits = (header or "").strip().lstrip("vV").split(".", 1)[0]
    return int(digits) if digits.isdigit() else 2
