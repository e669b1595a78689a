"""Flux (InfluxDB 2.x): quoting, the range and downsampling queries, pivoted tables to rows."""

from __future__ import annotations

import uuid
from collections.abc import Sequence
from datetime import UTC, datetime
from typing import Any

from server.kit import time as kit_time
from server.telemetry.influx_lines import MEASUREMENT, clamp_ns, rfc3339, window_us
from server.telemetry.store import Query

FLUX_META = frozenset({"result", "table", "asset_id", "seq"})


def flux_string(value: str) -> str:
    """A Flux double-quoted string literal."""
    return '"' + value.replace("\\", "\\\\").replace('"', '\\"').replace("${", "\\${") + '"'


def flux_base(bucket: str, asset_id: uuid.UUID, start_ns: int, stop_ns: int) -> str:
    """The Flux source of one asset's points in [start, stop)."""
    return (
        f"from(bucket: {flux_string(bucket)})\n"
        f"  |> range(start: {rfc3339(start_ns)}, stop: {rfc3339(stop_ns)})\n"
        f"  |> filter(fn: (r) => r._measurement == {flux_string(MEASUREMENT)} "
        f"and r.asset_id == {flux_string(str(asset_id))})\n"
    )


def flux_fields(fields: Sequence[str] | None, *, with_seq: bool) -> str:
    """A Flux filter keeping only the wanted fields (and `seq` when asked)."""
    if fields is None:
        return "" if with_seq else '  |> filter(fn: (r) => r._field != "seq")\n'
    wanted = (["seq"] if with_seq else []) + [f for f in fields if f != "seq"]
    return f"  |> filter(fn: (r) => contains(value: r._field, set: [{', '.join(map(flux_string, wanted))}]))\n"


PIVOT = (
    '  |> pivot(rowKey: ["_time"], columnKey: ["_field"], valueColumn: "_value")\n'
    '  |> group()\n  |> sort(columns: ["_time"])\n'
)


def flux_raw(q: Query, bucket: str) -> str:
    """Flux for raw rows, oldest first."""
    return (
        flux_base(bucket, q.asset_id, clamp_ns(q.start), clamp_ns(q.end))
        + flux_fields(q.fields, with_seq=True)
        + PIVOT
        + f"  |> limit(n: {max(1, q.limit)})\n"
    )


# types.isType needs Flux 0.141 (InfluxDB 2.2+); types.isNumeric would need 0.187
FLUX_IS_NUMBER = " or ".join(
    f'types.isType(v: r._value, type: "{t}")' for t in ("float", "int", "uint")
)


def flux_downsampled(q: Query, bucket: str) -> str:
    """Flux for one row per window (stamped with its start): mean/last of numbers, last of the rest."""
    every_us, offset_us = window_us(q)
    window = f"every: {every_us}us, offset: {offset_us}us"
    fn = "mean" if q.agg == "mean" else "last"
    return (
        'import "types"\n'
        + "data = "
        + flux_base(bucket, q.asset_id, clamp_ns(q.start), clamp_ns(q.end))
        + flux_fields(q.fields, with_seq=False)
        + f"num = data |> filter(fn: (r) => {FLUX_IS_NUMBER})\n"
        f'  |> aggregateWindow({window}, fn: {fn}, createEmpty: false, timeSrc: "_start")\n'
        f"other = data |> filter(fn: (r) => not ({FLUX_IS_NUMBER}))\n"
        f'  |> aggregateWindow({window}, fn: last, createEmpty: false, timeSrc: "_start")\n'
        "union(tables: [num, other])\n" + PIVOT + f"  |> limit(n: {max(1, q.limit)})\n"
    )


def rows_of_flux(tables: Any) -> list[dict[str, Any]]:
    """Pivoted Flux tables -> rows `{"ts": iso, field: value}` without nulls or Flux columns."""
    stamped: list[tuple[datetime, dict[str, Any]]] = []
    for table in tables:
        for record in table.records:
            ts = record.values["_time"].astimezone(UTC)
            row: dict[str, Any] = {"ts": kit_time.rfc3339(ts)}
            for key, value in record.values.items():
                if value is not None and not key.startswith("_") and key not in FLUX_META:
                    row[key] = value
            stamped.append((ts, row))
    stamped.sort(key=lambda pair: pair[0])
    return [row for _, row in stamped]
