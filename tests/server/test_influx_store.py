"""InfluxTelemetryStore against a real influxd 1.x of the test session's own (free port, temp dirs)."""

from __future__ import annotations

import threading
import uuid
from collections.abc import AsyncIterator
from datetime import UTC, datetime, timedelta
from statistics import fmean

import httpx
import pytest

from server.kit.time import rfc3339 as utc_z
from server.telemetry import influx_lines
from server.telemetry.influx import InfluxTelemetryStore
from server.telemetry.influx_flux import flux_downsampled
from server.telemetry.influx_lines import major_version, rfc3339, to_line, to_ns
from server.telemetry.sql import downsample
from server.telemetry.store import Aggregate, Query, Sample, flatten
from tests.server.influx_fixture import influxdb_url  # noqa: F401  (the session's influxd)

T0 = datetime(2026, 3, 1, 12, 0, 0, tzinfo=UTC)  # a multiple of 5 s since the epoch
END = T0 + timedelta(hours=1)


def sample(asset: uuid.UUID, i: int, **extra: object) -> Sample:
    """Sample number i of an asset, one second apart, with numeric, text and boolean fields."""
    payload = {
        "battery": {"voltage": 12.0 + i / 10, "pct": 100 - i},
        "mode": f"M{i}",
        "armed": i % 2 == 0,
        **extra,
    }
    return Sample(asset_id=asset, ts=T0 + timedelta(seconds=i), seq=i + 1, fields=flatten(payload))


def modes(rows: list[dict[str, object]]) -> list[object]:
    """The `mode` field of each row."""
    return [r["mode"] for r in rows]


@pytest.fixture
async def store(influxdb_url: str) -> AsyncIterator[InfluxTelemetryStore]:  # noqa: F811
    """A started store on its own database of the session's influxd."""
    s = InfluxTelemetryStore(influxdb_url, bucket=f"t_{uuid.uuid4().hex}")
    await s.start()
    yield s
    await s.close()


async def test_detects_the_1x_server(store: InfluxTelemetryStore) -> None:
    assert store.major == 1
    assert store.version.startswith("1.")


async def test_a_batch_is_formatted_off_the_event_loop(
    store: InfluxTelemetryStore, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Issue 48 finding 8: line protocol formatted on the event loop held it ~77 ms a 2,000-sample
    batch (p99 2-3 s at 1,000 UAVs). Each sample's line is made on a worker thread, and stored."""
    threads: list[threading.Thread] = []

    def traced(s: Sample) -> str | None:
        threads.append(threading.current_thread())
        return to_line(s)

    monkeypatch.setattr(influx_lines, "to_line", traced)
    asset = uuid.uuid4()
    await store.write([sample(asset, i) for i in range(2000)])
    assert len(threads) == 2000
    assert threading.main_thread() not in threads
    rows = await store.query(Query(asset_id=asset, start=T0, end=END))
    assert len(rows) == 2000


async def test_write_then_query_raw_rows_in_time_order(store: InfluxTelemetryStore) -> None:
    asset, other = uuid.uuid4(), uuid.uuid4()
    await store.write([sample(asset, i) for i in reversed(range(10))])
    await store.write([sample(other, i, extra_only_here=1.5) for i in range(3)])

    rows = await store.query(Query(asset_id=asset, start=T0, end=END))

    assert len(rows) == 10
    for i, row in enumerate(rows):
        assert row == {
            "ts": utc_z(T0 + timedelta(seconds=i)),
            "battery.voltage": pytest.approx(12.0 + i / 10),
            "battery.pct": 100 - i,
            "mode": f"M{i}",
            "armed": i % 2 == 0,
        }


async def test_query_raw_selects_fields_range_and_limit(store: InfluxTelemetryStore) -> None:
    asset = uuid.uuid4()
    await store.write([sample(asset, i) for i in range(10)])

    rows = await store.query(
        Query(
            asset_id=asset,
            start=T0 + timedelta(seconds=2),
            end=T0 + timedelta(seconds=7),
            fields=["mode"],
        )
    )
    assert [r["mode"] for r in rows] == ["M2", "M3", "M4", "M5", "M6"]  # [start, end)
    assert all(set(r) == {"ts", "mode"} for r in rows)

    limited = await store.query(Query(asset_id=asset, start=T0, end=END, limit=3))
    assert modes(limited) == ["M0", "M1", "M2"]
    assert await store.query(Query(asset_id=uuid.uuid4(), start=T0, end=END)) == []


async def test_query_downsampled_mean_of_numbers_last_of_the_rest(
    store: InfluxTelemetryStore,
) -> None:
    asset = uuid.uuid4()
    await store.write([sample(asset, i) for i in range(20)])

    rows = await store.query(Query(asset_id=asset, start=T0, end=END, every_s=5, agg="mean"))

    assert [r["ts"] for r in rows] == [utc_z(T0 + timedelta(seconds=5 * b)) for b in range(4)]
    for b, row in enumerate(rows):
        members = range(5 * b, 5 * b + 5)
        assert row["battery.voltage"] == pytest.approx(fmean(12.0 + i / 10 for i in members))
        assert row["battery.pct"] == pytest.approx(fmean(100 - i for i in members))
        assert row["mode"] == f"M{5 * b + 4}"
        assert row["armed"] is ((5 * b + 4) % 2 == 0)
        assert set(row) == {"ts", "battery.voltage", "battery.pct", "mode", "armed"}


async def test_query_downsampled_last_and_field_selection(store: InfluxTelemetryStore) -> None:
    asset = uuid.uuid4()
    await store.write([sample(asset, i) for i in range(20)])

    rows = await store.query(
        Query(
            asset_id=asset,
            start=T0 + timedelta(seconds=3),
            end=END,
            fields=["battery.pct", "mode"],
            every_s=10,
            agg="last",
        )
    )

    # buckets start at the range start (as in the SQL store), not at multiples of every_s
    assert rows == [
        {"ts": utc_z(T0 + timedelta(seconds=3)), "battery.pct": 88, "mode": "M12"},
        {"ts": utc_z(T0 + timedelta(seconds=13)), "battery.pct": 81, "mode": "M19"},
    ]


@pytest.mark.parametrize("agg", ["mean", "last"])
@pytest.mark.parametrize(("offset_s", "every_s"), [(0, 5), (2.5, 4), (0.25, 1.5)])
async def test_downsampling_matches_the_sql_store(
    store: InfluxTelemetryStore, agg: Aggregate, offset_s: float, every_s: float
) -> None:
    asset = uuid.uuid4()
    samples = [sample(asset, i) for i in range(0, 30) if i % 7 != 3]  # with gaps
    await store.write(samples)
    q = Query(asset, T0 + timedelta(seconds=offset_s), END, every_s=every_s, agg=agg)

    rows = await store.query(q)

    expected = downsample(
        [(s.ts, dict(s.fields)) for s in samples if s.ts >= q.start], q.start, every_s, agg
    )
    assert [r["ts"] for r in rows] == [r["ts"] for r in expected]
    assert rows == [{k: pytest.approx(v) for k, v in r.items()} for r in expected]


async def test_latest(store: InfluxTelemetryStore) -> None:
    asset = uuid.uuid4()
    assert await store.latest(asset) is None
    await store.write([sample(asset, i) for i in (3, 7, 5)])

    latest = await store.latest(asset)

    assert latest is not None
    assert latest["ts"] == utc_z(T0 + timedelta(seconds=7))
    assert latest["mode"] == "M7" and latest["battery.pct"] == 93
    assert "asset_id" not in latest


async def test_writing_the_same_batch_twice_stores_one_copy(store: InfluxTelemetryStore) -> None:
    asset = uuid.uuid4()
    batch = [sample(asset, i) for i in range(5)]
    await store.write(batch)
    await store.write(batch)

    rows = await store.query(Query(asset_id=asset, start=T0, end=END))
    assert modes(rows) == ["M0", "M1", "M2", "M3", "M4"]

    # the same (asset_id, ts) with other values overwrites in place
    await store.write([Sample(asset, batch[0].ts, 1, {"mode": "CHANGED"})])
    rows = await store.query(Query(asset_id=asset, start=T0, end=END))
    assert len(rows) == 5 and rows[0]["mode"] == "CHANGED"


async def test_prune_deletes_older_samples_and_counts_them(store: InfluxTelemetryStore) -> None:
    a, b = uuid.uuid4(), uuid.uuid4()
    await store.write([sample(a, i) for i in range(10)] + [sample(b, i) for i in range(4)])

    removed = await store.prune(T0 + timedelta(seconds=6))

    assert removed == 6 + 4
    rows = await store.query(Query(asset_id=a, start=T0, end=END))
    assert modes(rows) == ["M6", "M7", "M8", "M9"]
    assert await store.latest(b) is None
    assert await store.prune(T0 + timedelta(seconds=6)) == 0


async def test_bad_fields_are_dropped_not_fatal(store: InfluxTelemetryStore) -> None:
    asset = uuid.uuid4()
    await store.write([sample(asset, 0, time=5, nan=float("nan"))])
    # a field that changes type is refused by InfluxDB; the store logs it and carries on
    await store.write([Sample(asset, T0 + timedelta(seconds=1), 2, {"mode": 3.5})])
    await store.write([sample(asset, 2)])

    rows = await store.query(Query(asset_id=asset, start=T0, end=END))
    assert modes(rows) == ["M0", "M2"]
    assert "time" not in rows[0] and "nan" not in rows[0]


async def test_retention_policy_is_created_and_used(influxdb_url: str) -> None:  # noqa: F811
    db = f"t_{uuid.uuid4().hex}"
    store = InfluxTelemetryStore(influxdb_url, bucket=db, retention_s=2 * 3600)
    await store.start()
    try:
        now = datetime.now(UTC).replace(microsecond=0)
        asset = uuid.uuid4()
        await store.write([Sample(asset, now, 1, {"x": 1.0})])
        assert await store.latest(asset) == {"ts": utc_z(now), "x": 1}
    finally:
        await store.close()
    async with httpx.AsyncClient(base_url=influxdb_url) as http:
        r = await http.post("/query", data={"q": f'SHOW RETENTION POLICIES ON "{db}"'})
    policies = {v[0]: v for v in r.json()["results"][0]["series"][0]["values"]}
    assert policies["aerobase"][1] == "2h0m0s" and policies["aerobase"][4] is True


def test_pure_helpers() -> None:
    assert major_version("1.6.7~rc0") == 1 and major_version("v2.7.1") == 2
    assert major_version("3.0.1") == 3 and major_version(None) == 2
    assert to_ns(datetime(1970, 1, 1, 0, 0, 1, 5, tzinfo=UTC)) == 1_000_005_000
    assert rfc3339(1_000_005_000) == "1970-01-01T00:00:01.000005000Z"
    line = to_line(
        Sample(
            uuid.UUID(int=1),
            datetime(1970, 1, 1, tzinfo=UTC),
            7,
            {"a b": 2, "s": 'q"x', "ok": True},
        )
    )
    assert line == (
        'telemetry,asset_id=00000000-0000-0000-0000-000000000001 a\\ b=2,ok=true,s="q\\"x",seq=7i 0'
    )
    flux = flux_downsampled(Query(uuid.UUID(int=1), T0, END, every_s=1.5, agg="last"), "b")
    assert (
        "aggregateWindow(every: 1500000us, offset: 0us, fn: last" in flux
        and 'timeSrc: "_start"' in flux
    )


def test_line_protocol_is_what_influxdb_client_writes() -> None:
    """Our encoder (no Point object per sample) writes what influxdb-client's Point wrote, for
    keys and strings that need escaping, every value kind and the number-as-float rule; a nested
    payload is written flat, and its `asset_id` (the point's tag) is not a field."""
    from influxdb_client import Point, WritePrecision

    asset = uuid.uuid4()
    payload = {
        "asset_id": str(asset),
        "kind": "uav",
        "position": {"lat": 41.000513570518, "alt m": 120.0, "x,y=z": -1},
        "mode": 'say "hi"\\ now, a=b',
        "armed": False,
        "big": 12345678901234,
        "tiny": 1e-300,
        "none": None,
    }
    ts = datetime(2026, 11, 26, 12, 0, 0, 123456, tzinfo=UTC)
    ours = to_line(Sample(asset, ts, 42, payload))
    point = Point("telemetry").tag("asset_id", str(asset)).time(to_ns(ts), WritePrecision.NS)
    for name, value in flatten(payload).items():
        if name == "asset_id":
            continue
        is_number = isinstance(value, int | float) and not isinstance(value, bool)
        point.field(name, float(value) if is_number else value)
    point.field("seq", 42)
    assert ours == point.to_line_protocol()
    assert "asset_id=" + str(asset) + " " in (ours or "") and ",asset_id=" not in (ours or "")[60:]


async def test_a_nested_payload_reads_back_flat(store: InfluxTelemetryStore) -> None:
    """The ingest hands the store the payload as sent (nested); rows come back flat, as from
    the SQL store."""
    asset = uuid.uuid4()
    payload = {"asset_id": str(asset), "battery": {"pct": 80.0, "volts": 16.1}, "mode": "AUTO"}
    await store.write([Sample(asset, T0, 1, payload)])
    rows = await store.query(Query(asset_id=asset, start=T0, end=END))
    assert rows == [{"ts": utc_z(T0), "battery.pct": 80, "battery.volts": 16.1, "mode": "AUTO"}]
