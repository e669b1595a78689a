"""Values on the asset socket (issue 14, items 2 and 10): out of range, non-finite, or unstorable,
refused or dropped at the edge, and never failing another asset's messages in a shared batch."""

from __future__ import annotations

import asyncio
import json
import time
import uuid

import httpx
import websockets

from tests.conftest import LiveServer, Tenant
from tests.server.realtime_client import (
    asset_socket,
    asset_token,
    message,
    next_of,
    uav_sample,
    ws_url,
)


async def test_out_of_range_seq_and_ts_are_refused_and_another_asset_keeps_its_service(
    live_server: LiveServer, tenant: Tenant
) -> None:
    """ts = 1e17 ms and seq = 2^63 once failed the shared storage batch: the other asset's socket
    was closed with 1011. Now the offender is answered invalid_envelope (its socket stays open)
    and every message of the other asset is acked and stored."""
    bad_uav, good_uav = tenant.create_asset("uav"), tenant.create_asset("uav")
    bad_token, good_token = (
        asset_token(live_server.url, bad_uav),
        asset_token(live_server.url, good_uav),
    )
    bad_rows = [
        message("telemetry", uav_sample(), seq=1, ts=10**17),
        message("telemetry", uav_sample(), seq=2**63),
        message("event", {"name": "x"}, seq=2**63 - 1),
        message("telemetry", uav_sample(), seq=3, ts=-1),
    ]
    async with (
        asset_socket(live_server.url, bad_token) as bad,
        asset_socket(live_server.url, good_token) as good,
    ):
        for round_ in range(5):  # the bad rows and the good ones reach the same batches
            for i, row in enumerate(bad_rows):
                await bad.send(row)
                await good.send(
                    message("telemetry", uav_sample(round_ * 4 + i), seq=round_ * 4 + i + 1)
                )
        errors = [await next_of(bad, "error") for _ in range(5 * len(bad_rows))]
        last = 0
        while last < 20:
            last = (await next_of(good, "ack"))["payload"]["seq"]
        # the offender's socket is still served: a good message of its own is acked
        await bad.send(message("telemetry", uav_sample(), seq=4))
        assert (await next_of(bad, "ack"))["payload"]["seq"] == 4
    assert {e["payload"]["code"] for e in errors} == {"invalid_envelope"}
    assert any("ts" in e["payload"]["message"] for e in errors)
    assert any("seq" in e["payload"]["message"] for e in errors)
    async with httpx.AsyncClient(base_url=live_server.url) as c:
        rows = (
            await c.get(
                f"/api/v1/assets/{good_uav['id']}/telemetry",
                params={"start": "2000-01-01T00:00:00Z", "end": "2100-01-01T00:00:00Z"},
                headers=tenant.h("viewer"),
            )
        ).json()
    assert len(rows) == 20


async def test_an_unstorable_row_fails_alone_in_its_batch(database_url: str) -> None:
    """Rows that pass no edge (written straight to the ingest): the one the database cannot hold
    is rejected alone, every other row of the same batch is stored and acknowledged (SQLite and
    PostgreSQL)."""
    from datetime import UTC, datetime

    from sqlalchemy import insert

    from server.assets.models import Asset
    from server.kit.db import make_engine, make_sessionmaker
    from server.organizations.models import Organization
    from server.realtime.ingest import Ingest, Item
    from server.telemetry.sql import SqlTelemetryStore
    from server.telemetry.store import Query

    engine = make_engine(database_url)
    sessions = make_sessionmaker(engine)
    org, good, bad = uuid.uuid4(), uuid.uuid4(), uuid.uuid4()
    now = datetime.now(UTC)
    async with sessions() as db:
        await db.execute(
            insert(Organization).values(id=org, name=f"iso-{org.hex[:8]}", created_at=now)
        )
        for asset in (good, bad):
            await db.execute(
                insert(Asset).values(
                    id=asset, organization_id=org, name=f"iso-{asset.hex[:8]}", kind="uav",
                    description="", secret_hash="x", secret_rotated_at=now, attributes={},
                    created_at=now, updated_at=now,
                )
            )  # fmt: skip
        await db.commit()
    store = SqlTelemetryStore(sessions, engine.dialect.name)
    ingest = Ingest(sessions, store, max_delay_s=0.2)
    ingest.start()
    ts = int(time.time() * 1000)
    try:
        good_stream, bad_stream = uuid.uuid4(), uuid.uuid4()
        for stream, asset in ((good_stream, good), (bad_stream, bad)):
            await ingest.last_seq(stream, asset)
        heard_good, heard_bad = _Heard(), _Heard()
        items = [
            Item(good_stream, good, org, i, "telemetry", ts + i, {"n": i}, acks=heard_good)
            for i in range(1, 11)
        ]
        items.insert(
            5, Item(bad_stream, bad, org, 2**63, "telemetry", ts, {"n": -1}, acks=heard_bad)
        )
        for item in items:
            ingest.submit(item)
        await asyncio.wait_for(heard_good.reached(10), 30)
        await asyncio.wait_for(heard_bad.settled.wait(), 30)
    finally:
        await ingest.stop()
    assert heard_good.rejects == [] and heard_good.errors == []
    assert heard_bad.rejects == [2**63] and heard_bad.errors == []
    start = datetime.fromtimestamp(ts / 1000 - 60, UTC)
    end = datetime.fromtimestamp(ts / 1000 + 60, UTC)
    rows = await store.query(Query(good, start, end))
    assert sorted(r["n"] for r in rows) == list(range(1, 11))
    await engine.dispose()


class _Heard:
    """What the ingest told one connection (an `Acks`)."""

    def __init__(self) -> None:
        self.up_to = 0
        self.rejects: list[int] = []
        self.errors: list[BaseException] = []
        self.settled = asyncio.Event()

    def stored(self, seq: int) -> None:
        assert seq > self.up_to, "acks are cumulative and only move up"
        self.up_to = seq
        self.settled.set()

    def rejected(self, seq: int, reason: str) -> None:
        self.rejects.append(seq)
        self.settled.set()

    def failed(self, err: BaseException) -> None:
        self.errors.append(err)
        self.settled.set()

    async def reached(self, seq: int) -> None:
        while self.up_to < seq and not self.errors:
            self.settled.clear()
            await self.settled.wait()


async def test_nan_in_uav_telemetry_is_dropped_with_an_error_and_an_event(
    live_server: LiveServer, tenant: Tenant
) -> None:
    """NaN attitude over the raw socket was acked and silently not stored. Now the asset is told
    (invalid_payload naming the field), the rest of the sample is stored, and the asset's events
    record telemetry_field_dropped."""
    uav = tenant.create_asset("uav")
    token = asset_token(live_server.url, uav)
    sample = uav_sample(
        attitude={"roll_deg": float("nan"), "pitch_deg": 1.0, "yaw_deg": 2.0},
        battery={"percent": 80.0, "voltage_v": float("inf")},
    )
    async with asset_socket(live_server.url, token) as ws:
        text = message("telemetry", sample, seq=1)
        assert "NaN" in text and "Infinity" in text
        await ws.send(text)
        error = await next_of(ws, "error")
        assert (await next_of(ws, "ack"))["payload"]["seq"] == 1
    assert error["payload"]["code"] == "invalid_payload" and error["payload"]["re_seq"] == 1
    assert "payload.attitude.roll_deg" in error["payload"]["message"]
    assert "payload.battery.voltage_v" in error["payload"]["message"]
    async with httpx.AsyncClient(base_url=live_server.url, headers=tenant.h("viewer")) as c:
        latest = (await c.get(f"/api/v1/assets/{uav['id']}/telemetry/latest")).json()
        events = (
            await c.get(
                f"/api/v1/assets/{uav['id']}/events", params={"start": "2000-01-01T00:00:00Z"}
            )
        ).json()
    assert latest["position.lat"] == 41.0 and latest["battery.percent"] == 80.0
    assert "battery.voltage_v" not in latest and not any(k.startswith("attitude") for k in latest)
    dropped = [e for e in events if e["name"] == "telemetry_field_dropped"]
    assert len(dropped) == 1 and dropped[0]["severity"] == "warning"
    assert dropped[0]["data"]["fields"] == ["attitude.roll_deg", "battery.voltage_v"]


async def test_nan_reaches_no_operator_and_the_drop_event_does(
    live_server: LiveServer, tenant: Tenant
) -> None:
    """Operators get the kept sample (valid JSON, no NaN) and the telemetry_field_dropped event."""
    uav = tenant.create_asset("uav")
    token = asset_token(live_server.url, uav)
    async with websockets.connect(
        ws_url(live_server.url, "/ws/operator", tenant.tokens["viewer"])
    ) as op:
        await op.send(message("subscribe", {"asset_ids": [uav["id"]]}))
        async with asset_socket(live_server.url, token) as ws:
            await ws.send(message("telemetry", uav_sample(heading_deg=float("-inf")), seq=1))
            await next_of(ws, "ack")
        got = [json.loads(await asyncio.wait_for(op.recv(), 10)) for _ in range(2)]
    kinds = {m["type"]: m for m in got}
    assert (
        "heading_deg" not in kinds["telemetry"]["payload"]
        or kinds["telemetry"]["payload"]["heading_deg"] is None
    )
    assert kinds["event"]["payload"]["name"] == "telemetry_field_dropped"


async def test_nul_characters_are_stored_or_refused_never_fail_the_batch(
    live_server: LiveServer, tenant: Tenant
) -> None:
    """A NUL character is valid JSON but PostgreSQL's text cannot hold it: the event is stored
    without it, and the telemetry sample (JSON column) keeps it escaped."""
    uav = tenant.create_asset("uav")
    async with asset_socket(live_server.url, asset_token(live_server.url, uav)) as ws:
        await ws.send(
            message("event", {"name": "a\x00b", "message": "c\x00d", "data": {"e": "f\x00"}}, seq=1)
        )
        await ws.send(message("telemetry", uav_sample(flight_mode="AU\x00TO"), seq=2))
        replies = []
        while not any(r["type"] == "ack" and r["payload"]["seq"] == 2 for r in replies):
            replies.append(await next_of(ws, "ack", "error"))
    assert [r for r in replies if r["type"] == "error"] == []
    async with httpx.AsyncClient(base_url=live_server.url, headers=tenant.h("viewer")) as c:
        events = (
            await c.get(
                f"/api/v1/assets/{uav['id']}/events", params={"start": "2000-01-01T00:00:00Z"}
            )
        ).json()
        latest = (await c.get(f"/api/v1/assets/{uav['id']}/telemetry/latest")).json()
    assert [(e["name"], e["message"]) for e in events] == [("ab", "cd")]
    assert latest["flight_mode"] in ("AU\x00TO", "AUTO")
