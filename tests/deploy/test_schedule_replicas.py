"""Two replicas, one schedule, 20 due times: exactly 20 runs, none doubled, none missed.

Both `aerobase server` processes run the scheduler on one PostgreSQL database and Redis; each due
time must start one run, whichever replica claims it. Interval schedules are at least a minute
apart in production, so the replicas run with `AEROBASE_SCHEDULE_MIN_INTERVAL_S=1` (a documented
setting) and the schedule fires every 4 s: 20 real due times in 80 s, with the real clock, the
real row lock and the real unique (schedule, due time) key.

A UAV flies one run at a time, so each run must end before the next due time or that time would
be refused as `asset_busy` (a miss): the daemons, connected as real links to different replicas,
answer every availability check "not available" (rain), so each run is aborted at its first step,
as a scheduled run is on a rainy day, and the UAV is free again well within the interval.
"""

from __future__ import annotations

import base64
import uuid
from datetime import UTC, datetime, timedelta

import httpx
import pytest
from sqlalchemy import text
from sqlalchemy.ext.asyncio import create_async_engine

from assetlink.configfile import decrypt_config
from assetlink.dispatch import result
from assetlink.link import Link
from protocol.vocabulary import AvailabilityCondition, AvailabilityReport
from tests.conftest import Tenant
from tests.deploy.conftest import ROOT_EMAIL
from tests.polling import eventually
from tests.replicas import replicas

pytestmark = pytest.mark.slow

FINAL = ("completed", "incomplete", "aborted", "failed")
DUE_TIMES = 20
INTERVAL_S = 4


async def _runs_of(url: str, schedule_id: str) -> list[tuple[datetime, str, str | None]]:
    engine = create_async_engine(url)
    try:
        async with engine.connect() as conn:
            rows = await conn.execute(
                text(
                    "SELECT scheduled_for, state, cause FROM runs WHERE schedule_id = :id "
                    "ORDER BY scheduled_for"
                ),
                {"id": uuid.UUID(schedule_id)},
            )
            return [(at.replace(tzinfo=UTC), state, cause) for at, state, cause in rows]
    finally:
        await engine.dispose()


def _raining(request):  # type: ignore[no-untyped-def]
    rain = AvailabilityCondition(
        name="rain", ok=False, value=12.0, limit=2.0, message="rain 12 mm/h over the 2 mm/h limit"
    )
    return result("failed", "not available", AvailabilityReport.of([rain]).model_dump(mode="json"))


async def _link(url: str, asset: dict, folder) -> Link:  # type: ignore[no-untyped-def, type-arg]
    cfg = decrypt_config(base64.b64decode(asset["config_file"]), "asset-password-123")
    link = Link(url, cfg.name, cfg.secret, folder / f"{cfg.name}.db", seed=3)
    link.on_command("check_availability", _raining)
    await link.start()
    await link.wait_connected(20)
    return link


async def test_two_replicas_fire_each_of_20_due_times_of_one_schedule_exactly_once(
    own_database, tmp_path
):
    settings = {"AEROBASE_SCHEDULE_MIN_INTERVAL_S": "1"}
    with replicas(own_database, tmp_path, settings=settings) as servers:
        url_a, url_b = (f"http://127.0.0.1:{port}" for port, _ in servers)
        with httpx.Client(base_url=url_a, timeout=30) as api:
            tenant = Tenant(api, ROOT_EMAIL, "sched20")
            base = tenant.create_asset("landing_base")
            uav = tenant.create_asset("uav", base_id=base["id"])
        async with (
            httpx.AsyncClient(base_url=url_a, timeout=30) as a,
            httpx.AsyncClient(base_url=url_b, timeout=30) as b,
        ):
            mission = await a.post(
                "/api/v1/missions",
                headers=tenant.h("operator"),
                json={
                    "name": "patrol",
                    "items": [
                        {"command": 22, "lat": 41.178, "lon": -8.598, "alt": 20},
                        {"command": 20},
                    ],
                },
            )
            assert mission.status_code == 201, mission.text
            links = [await _link(url_a, uav, tmp_path), await _link(url_b, base, tmp_path)]
            try:
                first = (datetime.now(UTC) + timedelta(seconds=3)).replace(microsecond=0)
                r = await a.post(
                    "/api/v1/schedules",
                    headers=tenant.h("operator"),
                    json={
                        "name": "every 4 s",
                        "mission_id": mission.json()["id"],
                        "uav_id": uav["id"],
                        "base_id": base["id"],
                        "kind": "interval",
                        "interval_s": INTERVAL_S,
                        "at": first.isoformat(),
                    },
                )
                assert r.status_code == 201, r.text
                schedule_id = r.json()["id"]
                due = [first + timedelta(seconds=k * INTERVAL_S) for k in range(DUE_TIMES)]

                async def fired_last() -> bool:
                    runs = await _runs_of(own_database, schedule_id)
                    return any(at >= due[-1] for at, _, _ in runs)

                await eventually(fired_last, INTERVAL_S * DUE_TIMES + 60, "the 20th due time")
                r = await b.patch(
                    f"/api/v1/schedules/{schedule_id}",
                    headers=tenant.h("operator"),
                    json={"enabled": False},
                )
                assert r.status_code == 200, r.text
                last_result = r.json()["last_result"]

                async def window_ended() -> bool:
                    runs = await _runs_of(own_database, schedule_id)
                    return all(state in FINAL for at, state, _ in runs if at <= due[-1])

                await eventually(window_ended, 60, "the runs of the 20 due times to end")
            finally:
                for link in links:
                    await link.stop()

        runs = await _runs_of(own_database, schedule_id)
        window = [run for run in runs if run[0] <= due[-1]]
        assert [at for at, _, _ in window] == due, (last_result, window)
        # each run ended at its availability check, so the UAV was free for the next due time
        ended = {(state, cause) for _, state, cause in window}
        assert ended == {("aborted", "not_available")}, window
