"""Telemetry in InfluxDB: 1.x (HTTP /write + InfluxQL), 2.x (v2 write API + Flux), 3.x (v2 write + InfluxQL).

This module holds the store and its transport (httpx for /ping, /write and /query; influxdb-client
for the v2 APIs); the layout and line protocol are in `influx_lines`, the query text and answer
parsing of each dialect in `influx_ql` and `influx_flux`.

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
from datetime import datetime
from typing import Any

import httpx
from influxdb_client import InfluxDBClient, WritePrecision
from influxdb_client.client.write_api import SYNCHRONOUS
from influxdb_client.domain.bucket_retention_rules import BucketRetentionRules
from influxdb_client.rest import ApiException

from server.telemetry.influx_flux import (
    PIVOT,
    flux_base,
    flux_downsampled,
    flux_raw,
    flux_string,
    rows_of_flux,
)
from server.telemetry.influx_lines import (
    MEASUREMENT,
    NS_MAX,
    NS_MIN,
    InfluxStoreError,
    clamp_ns,
    encode_batch,
    major_version,
    rfc3339,
    to_ns,
)
from server.telemetry.influx_ql import (
    plain_rows,
    ql_downsampled,
    ql_ident,
    ql_raw,
    ql_string,
    rows_of_influxql,
)
from server.telemetry.store import Query, Sample

log = logging.getLogger(__name__)

WRITE_CHUNK = 5000


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

    in_database = False  # samples in InfluxDB; stream positions stay in SQL

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
                enable_gzip=True,  # the line-protocol batches, ~8x smaller
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
        names = {row.get("name") for row in plain_rows(body)}
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

    async def ping(self) -> None:
        """InfluxDB's /ping (204 on every major version); raises when unreachable."""
        if self._http is None:
            raise InfluxStoreError("the InfluxDB store is not started")
        r = await self._http.get("/ping")
        if r.status_code >= 400:
            raise InfluxStoreError(f"InfluxDB /ping answered {r.status_code}")

    # -- the TelemetryStore operations

    async def write(self, samples: Sequence[Sample], db: Any = None) -> None:
        """Store a batch; returns when InfluxDB has acknowledged it (points with bad values logged).
        `db` (the caller's SQL transaction) is not InfluxDB's: ignored."""
        v1 = self.major == 1
        # formatting and compressing off the event loop (at 1,000 UAVs x 10 Hz, formatting on
        # it was 65 % of the server's time and held the loop ~77 ms a batch: p99 2-3 s)
        for chunk in await asyncio.to_thread(encode_batch, samples, WRITE_CHUNK, v1):
            if isinstance(chunk, bytes):
                await self._write_v1(chunk)
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
        for row in plain_rows(body):
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
        counted = plain_rows(
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

    async def _write_v1(self, body: bytes) -> None:
        """One gzip-compressed line-protocol body to /write."""
        params = {"db": self._db, "precision": "ns", **({"rp": self._rp} if self._rp else {})}
        try:
            r = await self._need_http().post(
                "/write",
                params=params,
                content=body,
                headers={"Content-Encoding": "gzip"},
            )
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
