"""InfluxQL (InfluxDB 1.x and 3.x): quoting, the range and downsampling queries, answers to rows."""

from __future__ import annotations

from typing import Any

from server.telemetry.influx_lines import InfluxStoreError, clamp_ns, iso_of_ns, window_us
from server.telemetry.store import Query


def ql_ident(name: str) -> str:
    """An InfluxQL double-quoted identifier."""
    return '"' + name.replace("\\", "\\\\").replace('"', '\\"') + '"'


def ql_string(value: str) -> str:
    """An InfluxQL single-quoted string literal."""
    return "'" + value.replace("\\", "\\\\").replace("'", "\\'") + "'"


def ql_raw(q: Query, source: str) -> str:
    """InfluxQL for raw rows of one asset in [start, end), oldest first."""
    cols = "*" if q.fields is None else ", ".join(ql_ident(f) for f in ["seq", *q.fields])
    return (
        f"SELECT {cols} FROM {source} WHERE {_ql_where(q)} "
        f"ORDER BY time ASC LIMIT {max(1, q.limit)}"
    )


def ql_downsampled(q: Query, source: str, numeric: dict[str, bool]) -> str | None:
    """InfluxQL for one row per bucket: MEAN/LAST of numbers, LAST of anything else."""
    names = [f for f in (q.fields if q.fields is not None else sorted(numeric)) if f in numeric]
    names = [f for f in names if f != "seq"]
    if not names:
        return None
    every, offset = window_us(q)
    aggs = ", ".join(
        f"{'MEAN' if q.agg == 'mean' and numeric[f] else 'LAST'}({ql_ident(f)}) AS {ql_ident(f)}"
        for f in names
    )
    return (
        f"SELECT {aggs} FROM {source} WHERE {_ql_where(q)} "
        f"GROUP BY time({every}u, {offset}u) fill(none) LIMIT {max(1, q.limit)}"
    )


def _ql_where(q: Query) -> str:
    return (
        f"asset_id = {ql_string(str(q.asset_id))} AND time >= {clamp_ns(q.start)} "
        f"AND time < {clamp_ns(q.end)}"
    )


def rows_of_influxql(body: dict[str, Any], floor_ns: int | None = None) -> list[dict[str, Any]]:
    """An InfluxQL JSON answer (epoch=ns) -> rows `{"ts": iso, field: value}` without nulls."""
    rows: list[dict[str, Any]] = []
    for result in body.get("results", []):
        if "error" in result:
            raise InfluxStoreError(result["error"])
        for series in result.get("series", []):
            columns = series["columns"]
            for values in series.get("values", []):
                record = dict(zip(columns, values, strict=True))
                ns = int(record.pop("time"))
                if floor_ns is not None:
                    ns = max(ns, floor_ns)  # the first bucket may start before the range
                record.pop("asset_id", None)
                record.pop("seq", None)  # stored for the record, not part of a row (as in SQL)
                rows.append(
                    {"ts": iso_of_ns(ns), **{k: v for k, v in record.items() if v is not None}}
                )
    return rows


def plain_rows(body: dict[str, Any]) -> list[dict[str, Any]]:
    """Every series' rows of an InfluxQL answer as dicts (column -> value), nothing dropped."""
    return [
        dict(zip(series["columns"], values, strict=True))
        for result in body.get("results", [])
        for series in result.get("series", [])
        for values in series.get("values", [])
    ]
