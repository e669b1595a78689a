"""Migrations: upgrade, downgrade to base, upgrade again; models and migrations agree."""

from __future__ import annotations

import asyncio
import tempfile
import uuid
from datetime import UTC, datetime

import pytest
import sqlalchemy as sa
from alembic.autogenerate import compare_metadata
from alembic.migration import MigrationContext
from sqlalchemy.ext.asyncio import create_async_engine

from server import migrate
from server.kit.db import Base, UTCDateTime
from tests.conftest import _reset_postgres, need_service


def fresh_postgres(name: str) -> str:
    """The URL of an empty PostgreSQL database `name` of the calling test's own (dropped and made
    again), so the suite's live server, which may use /test, is not disturbed."""
    need_service("PostgreSQL", "127.0.0.1", 5432)
    import asyncpg

    async def make_db() -> None:
        conn = await asyncpg.connect("postgresql://postgres@127.0.0.1:5432/postgres")
        await conn.execute(f"DROP DATABASE IF EXISTS {name}")
        await conn.execute(f"CREATE DATABASE {name}")
        await conn.close()

    asyncio.run(make_db())
    url = f"postgresql+asyncpg://postgres@127.0.0.1:5432/{name}"
    _reset_postgres(url)
    return url


def _diff(url: str) -> list:
    import server.models  # noqa: F401

    async def run() -> list:
        engine = create_async_engine(url)
        async with engine.connect() as conn:
            diff = await conn.run_sync(
                lambda c: compare_metadata(MigrationContext.configure(c), Base.metadata)
            )
        await engine.dispose()
        return diff

    return asyncio.run(run())


def _cycle(url: str) -> None:
    migrate.upgrade(url)
    assert _diff(url) == [], "models and migrations disagree: run alembic revision --autogenerate"
    migrate.downgrade(url, "base")
    migrate.upgrade(url)
    assert _diff(url) == []


@pytest.mark.slow
def test_sqlite_upgrade_downgrade_upgrade_and_no_autogenerate_diff():
    with tempfile.TemporaryDirectory() as tmp:
        _cycle(f"sqlite+aiosqlite:///{tmp}/m.db")


@pytest.mark.slow
def test_postgresql_upgrade_downgrade_upgrade_and_no_autogenerate_diff():
    _cycle(fresh_postgres("aerobase_migrations"))


# --- 0005: runs' step commands and flight facts move out of JSON into a table and columns ---


def _col(name: str) -> sa.ColumnClause:
    """A column typed by its name: ids are UUIDs, *_at and deadline UTC times."""
    if name == "id" or name.endswith("_id"):
        return sa.column(name, sa.Uuid())
    if name.endswith("_at") or name in ("deadline", "lease_until"):
        return sa.column(name, UTCDateTime())
    return sa.column(name)


_ORGS = sa.table("organizations", *(_col(c) for c in ("id", "name")), _col("created_at"))  # fmt: skip
_ASSETS = sa.table(
    "assets",
    *(_col(c) for c in ("id", "organization_id", "name", "kind", "description", "secret_hash")),
    sa.column("attributes", sa.JSON()),
    *(_col(c) for c in ("secret_rotated_at", "created_at", "updated_at")),
)  # fmt: skip
_MISSIONS = sa.table(
    "missions",
    *(_col(c) for c in ("id", "organization_id", "name", "description", "kind", "source")),
    *(sa.column(c, sa.JSON()) for c in ("items", "extras")),
    *(_col(c) for c in ("created_at", "updated_at")),
)  # fmt: skip
_COMMANDS = sa.table(
    "commands",
    *(_col(c) for c in ("id", "organization_id", "asset_id", "name", "status", "reason")),
    sa.column("params", sa.JSON()),
    *(_col(c) for c in ("deadline", "created_at", "updated_at")),
)  # fmt: skip
_RUN_COLUMNS = ("id", "organization_id", "mission_id", "uav_id", "base_id", "state", "actions_issued",
                "aborting", "abort_requested", "abort_reason", "reason", "alert")  # fmt: skip
_RUNS_0004 = sa.table(
    "runs",
    *(_col(c) for c in _RUN_COLUMNS),
    *(sa.column(c, sa.JSON()) for c in ("step_commands", "facts")),
    *(_col(c) for c in ("step_started_at", "lease_until", "created_at", "updated_at")),
)  # fmt: skip
_RUNS_0005 = sa.table(
    "runs",
    *(_col(c) for c in ("id", "flight_started_at", "flight_ended_at")),
    sa.column("landing_error_m", sa.Float()),
)
_STEP = sa.table(
    "run_step_commands",
    *(_col(c) for c in ("run_id", "position", "target", "command", "command_id")),
)


def _seed_0004(conn: sa.Connection) -> dict:
    now = datetime(2026, 11, 23, 10, 0, tzinfo=UTC)
    org, uav, base, mission, cmd = (uuid.uuid4() for _ in range(5))
    conn.execute(_ORGS.insert().values(id=org, name="porto", created_at=now))
    for aid, kind in ((uav, "uav"), (base, "landing_base")):
        conn.execute(
            _ASSETS.insert().values(
                id=aid, organization_id=org, name=kind, kind=kind, description="",
                secret_hash="x" * 64, attributes={}, secret_rotated_at=now, created_at=now,
                updated_at=now,
            )
        )  # fmt: skip
    conn.execute(
        _MISSIONS.insert().values(
            id=mission, organization_id=org, name="m", description="", kind="waypoints",
            source="api", items=[{"command": 20}], extras={}, created_at=now, updated_at=now,
        )
    )  # fmt: skip
    conn.execute(
        _COMMANDS.insert().values(
            id=cmd, organization_id=org, asset_id=uav, name="start_mission", status="sent",
            reason="", params={}, deadline=now, created_at=now, updated_at=now,
        )
    )  # fmt: skip
    started = "2026-11-23T10:05:00+00:00"
    runs = {
        # in flight: its start_mission out, the take-off time recorded
        "flying": ({"uav:start_mission": str(cmd)}, {"flight_started_at": started}, True),
        # closing after an abort: stop and close still to issue, the flight and its error done
        "closing": (
            {},
            {
                "flight_started_at": started,
                "flight_ended_at": "2026-11-23T10:20:30+00:00",
                "landing_error_m": 0.12,
                "pending_actions": [
                    {"target": "base", "command": "stop", "params": {}},
                    {"target": "base", "command": "close", "params": {}},
                ],
            },
            False,
        ),
    }
    ids = {}
    for state, (step_commands, facts, issued) in runs.items():
        ids[state] = uuid.uuid4()
        conn.execute(
            _RUNS_0004.insert().values(
                id=ids[state], organization_id=org, mission_id=mission, uav_id=uav, base_id=base,
                state=state, actions_issued=issued, aborting=False, abort_requested=False,
                abort_reason="", reason="", alert=False, step_commands=step_commands,
                facts=facts, step_started_at=now, lease_until=now, created_at=now,
                updated_at=now,
            )
        )  # fmt: skip
    return {"runs": runs, "ids": ids, "command": cmd}


def _run_sync(url: str, fn):  # type: ignore[no-untyped-def]
    async def run():  # type: ignore[no-untyped-def]
        engine = create_async_engine(url)
        async with engine.begin() as conn:
            out = await conn.run_sync(fn)
        await engine.dispose()
        return out

    return asyncio.run(run())


def _check_data_migration(url: str) -> None:
    migrate.upgrade(url, "0004")
    seeded = _run_sync(url, _seed_0004)
    migrate.upgrade(url)

    def read_0005(conn: sa.Connection) -> tuple[dict, dict]:
        runs = {r.id: r for r in conn.execute(sa.select(_RUNS_0005))}
        steps: dict = {}
        for r in conn.execute(sa.select(_STEP).order_by(_STEP.c.position)):
            steps.setdefault(r.run_id, []).append((r.target, r.command, r.command_id))
        return runs, steps

    runs, steps = _run_sync(url, read_0005)
    flying, closing = seeded["ids"]["flying"], seeded["ids"]["closing"]
    assert runs[flying].flight_started_at == datetime(2026, 11, 23, 10, 5, tzinfo=UTC)
    assert runs[flying].flight_ended_at is None and runs[flying].landing_error_m is None
    assert runs[closing].flight_ended_at == datetime(2026, 11, 23, 10, 20, 30, tzinfo=UTC)
    assert runs[closing].landing_error_m == 0.12
    assert steps[flying] == [("uav", "start_mission", seeded["command"])]
    assert steps[closing] == [("base", "stop", None), ("base", "close", None)]

    migrate.downgrade(url, "0004")
    back = _run_sync(
        url, lambda c: {r.id: (r.step_commands, r.facts) for r in c.execute(sa.select(_RUNS_0004))}
    )
    for state, (step_commands, facts, _issued) in seeded["runs"].items():
        assert back[seeded["ids"][state]] == (step_commands, facts), state
    migrate.upgrade(url)


@pytest.mark.slow
def test_sqlite_0005_carries_runs_over_both_ways():
    with tempfile.TemporaryDirectory() as tmp:
        _check_data_migration(f"sqlite+aiosqlite:///{tmp}/m.db")


@pytest.mark.slow
def test_postgresql_0005_carries_runs_over_both_ways():
    _check_data_migration(fresh_postgres("aerobase_migrations_data"))
