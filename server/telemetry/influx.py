"""Telemetry in InfluxDB: 1.x (HTTP /write + InfluxQL), 2.x (v2 write API + Flux), 3.x (v2 write + InfluxQL).

Layout: measurement `telemetry`, tag `asset_id`, one field per flat sample field plus the integer
field `seq`, timestamp in nanoseconds. Numbers other than `seq` are stored as floats so a field
never changes type between samples (InfluxDB refuses a type change within a shard).

Exactly-once: a point is identified by (measurement, tag set, timestamp), so writing the same
(asset_id, ts) again overwrites its field values instead of adding a row; replaying a batch after
a lost acknowledgement is harmless. The flip side: two different samples of one asset with the
same timestamp (to the microsecond a `datetime` carries) are merged into one point.
"""

from __future__ import annotations

import asyncio
import logging
import uuid
from collections.abc import Sequence
from datetime import UTC, datetime, timedelta
from typing import Any

import httpx
from influxdb_client import InfluxDBClient, Point, WritePrecision
from influxdb_client.client.write_api import SYNCHRONOUS
from influxdb_client.domain.bucket_retention_rules import BucketRetentionRules
from influxdb_client.rest import ApiException

from server.telemetry.store import Query, Sample

log = logging.getLogger(__name__)

MEASUREMENT = "telemetry"
EPOCH = datetime(1970, 1, 1, tzinfo=UTC)
NS_MIN, NS_MAX = -9_223_372_036_854_775_806, 9_223_372_036_854_775_806  # InfluxDB's time range
RESERVED = frozenset({"time", "seq", "asset_id", "_time", "_field", "_value", "_measurement"})
WRITE_CHUNK = 5000
FLUX_META = frozenset({"result", "table", "asset_id", "seq"})


class InfluxStoreError(RuntimeError):
    """InfluxDB refused or failed a request that may succeed when retried."""


# ---------------------------------------------------------------- pure helpers


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
    """Integer nanoseconds -> ISO 8601 UTC (microsecond resolution, like our datetimes)."""
    return (EPOCH + timedelta(microseconds=ns // 1000)).isoformat()


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


def ql_ident(name: str) -> str:
    """An InfluxQL double-quoted identifier."""
    return '"' + name.replace("\\", "\\\\").replace('"', '\\"') + '"'


def ql_string(value: str) -> str:
    """An InfluxQL single-quoted string literal."""
    return "'" + value.replace("\\", "\\\\").replace("'", "\\'") + "'"


def flux_string(value: str) -> str:
    """A Flux double-quoted string literal."""
    return '"' + value.replace("\\", "\\\\").replace('"', '\\"').replace("${", "\\${") + '"'


def window_us(q: Query) -> tuple[int, int]:
    """Bucket width and offset in microseconds: buckets start at `q.start` + k * `q.every_s`."""
    every = max(1, round((q.every_s or 1) * 1_000_000))
    return every, (clamp_ns(q.start) // 1000) % every


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
            row: dict[str, Any] = {"ts": ts.isoformat()}
            for key, value in record.values.items():
                if value is not None and not key.startswith("_") and key not in FLUX_META:
                    row[key] = value
            stamped.append((ts, row))
    stamped.sort(key=lambda pair: pair[0])
    return [row for _, row in stamped]


def major_version(header: str | None) -> int:
    """The major version from X-Influxdb-Version ("1.6.7~rc0", "v2.7.1", "3.0.1"); 2 if unknown."""
    digits = (header or "").strip().lstrip("vV").split(".", 1)[0]
    return int(digits) if digits.isdigit() else 2


# ---------------------------------------------------------------- the store


class InfluxTelemetryStore:
    """`TelemetryStore` on InfluxDB; the server's major version (from /ping) picks the dialect.

    1.x: line protocol to /write?db=&rp=, InfluxQL on /query; `bucket` is "db" or "db/rp",
    credentials are username/password (or token "user:password"). 2.x: influxdb-client's v2 write
    and Flux query APIs (token or username/password, `org`), the delete API for `prune`. 3.x: the v2
    write API and InfluxQL on /query (database = `bucket`); `prune` is left to the database's own
    retention period. HTTP calls use httpx's async client; influxdb-client calls run in a worker
    thread. Rows have the SQL store's shape: ranges are [start, end), buckets start at `start`
    and are `every_s` wide (to the microsecond), `seq` is stored but not returned.
    """

    def __init__(
        self,
        url: str,
        *,
        org: str = "aerobase",
        bucket: str = "aerobase",
        token: str | None = None,
        username: str | None = None,
        password: str | None = None,
        retention_s: int | None = None,
        timeout_s: float = 10.0,
    ) -> None:
        self.url = url.rstrip("/")
        self.org, self.bucket, self.token = org, bucket, token
        self.username, self.password = username, password
        self.retention_s, self.timeout_s = retention_s, timeout_s
        self.version = ""
        self.major = 0
        db, _, rp = bucket.partition("/")
        self._db, self._rp = db, rp or None
        self._http: httpx.AsyncClient | None = None
        self._client: InfluxDBClient | None = None

    # -- lifecycle

    async def start(self) -> None:
        """Detect the server version, then create the database/bucket and retention where needed."""
        headers, auth = {}, None
        if self.token and ":" in self.token and not self.username:
            self.username, _, self.password = self.token.partition(":")
        if self.username is not None:
            auth = httpx.BasicAuth(self.username, self.password or "")
        elif self.token:
            headers["Authorization"] = f"Token {self.token}"
        self._http = httpx.AsyncClient(
            base_url=self.url, headers=headers, auth=auth, timeout=self.timeout_s
        )
        try:
            r = await self._http.get("/ping")
        except httpx.HTTPError as err:
            raise InfluxStoreError(f"InfluxDB at {self.url} is unreachable: {err}") from err
        self.version = r.headers.get("X-Influxdb-Version", "")
        self.major = major_version(self.version)
        log.info("InfluxDB %s at %s (major %d)", self.version or "?", self.url, self.major)
        if self.major == 1:
            await self._start_v1()
        else:
            self._client = InfluxDBClient(
                url=self.url,
                token=self.token or "",
                org=self.org,
                username=self.username,
                password=self.password,
                timeout=int(self.timeout_s * 1000),
            )
            if self.major == 2:
                await asyncio.to_thread(self._ensure_bucket)

    async def _start_v1(self) -> None:
        await self._ql(f"CREATE DATABASE {ql_ident(self._db)}")
        if self.retention_s is None:
            return
        self._rp = self._rp or "aerobase"
        seconds = max(3600, int(self.retention_s))  # InfluxDB 1.x refuses less than an hour
        body = await self._ql(f"SHOW RETENTION POLICIES ON {ql_ident(self._db)}")
        names = {row.get("name") for row in _plain_rows(body)}
        verb = "ALTER" if self._rp in names else "CREATE"
        extra = "" if verb == "ALTER" else " REPLICATION 1"
        await self._ql(
            f"{verb} RETENTION POLICY {ql_ident(self._rp)} ON {ql_ident(self._db)} "
            f"DURATION {seconds}s{extra} DEFAULT"
        )

    def _ensure_bucket(self) -> None:
        assert self._client is not None
        api = self._client.buckets_api()
        if api.find_bucket_by_name(self.bucket) is not None:
            return
        rules = (
            [BucketRetentionRules(type="expire", every_seconds=int(self.retention_s))]
            if self.retention_s
            else []
        )
        api.create_bucket(bucket_name=self.bucket, retention_rules=rules, org=self.org)

    async def close(self) -> None:
        """Close the HTTP client and influxdb-client (writes are synchronous: nothing to flush)."""
        if self._http is not None:
            await self._http.aclose()
            self._http = None
        if self._client is not None:
            await asyncio.to_thread(self._client.close)
            self._client = None

    # -- the TelemetryStore operations

    async def write(self, samples: Sequence[Sample]) -> None:
        """Store a batch; returns when InfluxDB has acknowledged it (points with bad values logged)."""
        lines = [line for line in map(to_line, samples) if line is not None]
        for i in range(0, len(lines), WRITE_CHUNK):
            chunk = lines[i : i + WRITE_CHUNK]
            if self.major == 1:
                await self._write_v1("\n".join(chunk))
            else:
                await asyncio.to_thread(self._write_v2, chunk)

    async def query(self, q: Query) -> list[dict[str, Any]]:
        """Rows `{"ts": iso8601, field: value, ...}` oldest first (the SQL store's shape)."""
        if self.major == 2:
            flux = flux_downsampled(q, self.bucket) if q.every_s else flux_raw(q, self.bucket)
            return await self._flux(flux)
        if not q.every_s:
            return rows_of_influxql(await self._ql(ql_raw(q, self._source())))
        body = await self._ql(f"SHOW FIELD KEYS FROM {self._source()}")
        numeric: dict[str, bool] = {}
        for row in _plain_rows(body):
            name, is_num = row["fieldKey"], row["fieldType"] in ("float", "integer")
            numeric[name] = numeric.get(name, True) and is_num
        text = ql_downsampled(q, self._source(), numeric)
        if text is None:
            return []
        return rows_of_influxql(await self._ql(text), floor_ns=clamp_ns(q.start))

    async def latest(self, asset_id: uuid.UUID) -> dict[str, Any] | None:
        """The newest sample of an asset as a row, or None."""
        if self.major == 2:
            base = flux_base(self.bucket, asset_id, NS_MIN, NS_MAX)
            last = await self._flux(
                base + '  |> filter(fn: (r) => r._field == "seq")\n  |> last()\n' + PIVOT
            )
            if not last:
                return None
            ns = to_ns(datetime.fromisoformat(last[0]["ts"]))
            rows = await self._flux(flux_base(self.bucket, asset_id, ns, ns + 1000) + PIVOT)
            return rows[-1] if rows else None
        text = (
            f"SELECT * FROM {self._source()} WHERE asset_id = {ql_string(str(asset_id))} "
            "ORDER BY time DESC LIMIT 1"
        )
        rows = rows_of_influxql(await self._ql(text))
        return rows[0] if rows else None

    async def prune(self, before: datetime) -> int:
        """Delete samples older than `before`; returns how many there were (counted just before)."""
        cut = clamp_ns(before)
        if self.major == 2:
            tables = await self._flux_tables(
                f"from(bucket: {flux_string(self.bucket)})\n"
                f"  |> range(start: {rfc3339(NS_MIN)}, stop: {rfc3339(cut)})\n"
                f'  |> filter(fn: (r) => r._measurement == "{MEASUREMENT}" and r._field == "seq")\n'
                "  |> group()\n  |> count()\n"
            )
            await asyncio.to_thread(self._delete_v2, cut - 1)
            return sum(int(record.get_value()) for table in tables for record in table.records)
        if self.major != 1:
            log.warning(
                "InfluxDB %s: prune is left to the database's retention period", self.version
            )
            return 0
        counted = _plain_rows(
            await self._ql(f'SELECT COUNT("seq") AS n FROM {self._source()} WHERE time < {cut}')
        )
        await self._ql(f"DELETE FROM {ql_ident(MEASUREMENT)} WHERE time < {cut}")
        return int(counted[0].get("n") or 0) if counted else 0

    # -- transport

    def _source(self) -> str:
        if self._rp:
            return f"{ql_ident(self._rp)}.{ql_ident(MEASUREMENT)}"
        return ql_ident(MEASUREMENT)

    def _need_http(self) -> httpx.AsyncClient:
        if self._http is None:
            raise InfluxStoreError("InfluxTelemetryStore is not started")
        return self._http

    async def _ql(self, text: str) -> dict[str, Any]:
        """Run InfluxQL on /query (POST, epoch=ns); raise InfluxStoreError on any error."""
        try:
            r = await self._need_http().post(
                "/query", data={"q": text, "db": self._db, "epoch": "ns"}
            )
        except httpx.HTTPError as err:
            raise InfluxStoreError(f"InfluxDB query failed: {err}") from err
        if r.status_code != 200:
            raise InfluxStoreError(f"InfluxDB query failed ({r.status_code}): {r.text[:500]}")
        body: dict[str, Any] = r.json()
        for result in body.get("results", []):
            if "error" in result:
                raise InfluxStoreError(f"InfluxQL error: {result['error']} in {text[:200]}")
        return body

    async def _write_v1(self, body: str) -> None:
        params = {"db": self._db, "precision": "ns", **({"rp": self._rp} if self._rp else {})}
        try:
            r = await self._need_http().post("/write", params=params, content=body.encode())
        except httpx.HTTPError as err:
            raise InfluxStoreError(f"InfluxDB write failed: {err}") from err
        if r.status_code == 400:
            # bad points (a field changing type, a parse error): the good ones are stored
            log.warning("InfluxDB refused some telemetry points: %s", r.text[:500])
        elif r.status_code >= 300:
            raise InfluxStoreError(f"InfluxDB write failed ({r.status_code}): {r.text[:500]}")

    def _write_v2(self, lines: list[str]) -> None:
        assert self._client is not None
        try:
            with self._client.write_api(write_options=SYNCHRONOUS) as api:
                api.write(
                    bucket=self.bucket,
                    org=self.org,
                    record=lines,
                    write_precision=WritePrecision.NS,
                )
        except ApiException as err:
            if err.status in (400, 422):
                log.warning("InfluxDB refused some telemetry points: %s", err.body)
                return
            raise InfluxStoreError(f"InfluxDB write failed ({err.status}): {err.body}") from err
        except Exception as err:  # urllib3 connection errors and the like: retryable
            raise InfluxStoreError(f"InfluxDB write failed: {err}") from err

    async def _flux(self, flux: str) -> list[dict[str, Any]]:
        return rows_of_flux(await self._flux_tables(flux))

    async def _flux_tables(self, flux: str) -> Any:
        client = self._client
        if client is None:
            raise InfluxStoreError("InfluxTelemetryStore is not started")
        try:
            tables = await asyncio.to_thread(client.query_api().query, flux, org=self.org)
        except Exception as err:
            raise InfluxStoreError(f"Flux query failed: {err}") from err
        return tables

    def _delete_v2(self, stop_ns: int) -> None:
        assert self._client is not None
        self._client.delete_api().delete(
            start=rfc3339(NS_MIN),
            stop=rfc3339(stop_ns),
            predicate=f'_measurement="{MEASUREMENT}"',
            bucket=self.bucket,
            org=self.org,
        )


def _plain_rows(body: dict[str, Any]) -> list[dict[str, Any]]:
    """Every series' rows of an InfluxQL answer as dicts (column -> value), nothing dropped."""
    return [
        dict(zip(series["columns"], values, strict=True))
        for result in body.get("results", [])
        for series in result.get("series", [])
        for values in series.get("values", [])
    ]
