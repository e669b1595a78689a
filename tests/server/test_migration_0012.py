"""0012 re-judges the runs already recorded: a completed run that the battery reserve (or the
geofence, or its time budget) turned home is `incomplete` with that cause; one whose charging
failed is `completed_with_issues` (`charging_refused`); a clean one stays `completed`; and the
downgrade gives the old words back (an early return's cause kept on its run)."""

from __future__ import annotations

import itertools
import tempfile
import uuid
from datetime import UTC, datetime, timedelta

import pytest
import sqlalchemy as sa

from server import migrate
from tests.server.test_migrations import (
    _ASSETS,
    _MISSIONS,
    _ORGS,
    _RUN_COLUMNS,
    _col,
    _run_sync,
    fresh_postgres,
)

_RUNS = sa.table(
    "runs",
    *(_col(c) for c in (*_RUN_COLUMNS, "outcome", "cause")),
    *(_col(c) for c in ("step_started_at", "lease_until", "created_at", "updated_at")),
)
_RUNS_0012 = sa.table(
    "runs", *(_col(c) for c in ("id", "state", "outcome", "cause")), sa.column("issues", sa.JSON())
)
_TRANSITIONS = sa.table(
    "run_transitions",
    *(_col(c) for c in ("id", "run_id", "at", "from_state", "to_state", "reason", "cause")),
)
# (flying exit's cause, the final transition's cause) -> (state, outcome, cause, issues) after 0012
RUNS = {
    "clean": (("", ""), ("completed", "completed", None, [])),
    "reserve": (("battery_reserve", ""), ("incomplete", "incomplete", "battery_reserve", [])),
    "charging": (
        ("", "charging_failed"),
        ("completed", "completed_with_issues", "charging_refused", ["charging_refused"]),
    ),
}


def _seed(conn: sa.Connection) -> dict[str, uuid.UUID]:
    now = datetime(2026, 12, 1, 10, 0, tzinfo=UTC)
    org, uav, base, mission = (uuid.uuid4() for _ in range(4))
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
    ids = {}
    for name, ((returned, cause), _) in RUNS.items():
        ids[name] = run = uuid.uuid4()
        conn.execute(
            _RUNS.insert().values(
                id=run, organization_id=org, mission_id=mission, uav_id=uav, base_id=base,
                state="completed", outcome="completed", cause=cause or None, actions_issued=True,
                aborting=False, abort_requested=False, abort_reason="", reason="", alert=False,
                step_started_at=now, lease_until=now, created_at=now, updated_at=now,
            )
        )  # fmt: skip
        steps = ["pending", "checking", "opening", "uploading", "flying", "landing",
                 "confirming", "closing", "charging", "completed"]  # fmt: skip
        for i, (a, b) in enumerate(itertools.pairwise(steps)):
            conn.execute(
                _TRANSITIONS.insert().values(
                    id=uuid.uuid4(), run_id=run, at=now + timedelta(seconds=i), from_state=a,
                    to_state=b, reason="",
                    cause=returned if a == "flying" else cause if b == "completed" else "",
                )
            )  # fmt: skip
    return ids


def _read(conn: sa.Connection) -> dict[uuid.UUID, tuple]:
    return {
        r.id: (r.state, r.outcome, r.cause, list(r.issues))
        for r in conn.execute(sa.select(_RUNS_0012))
    }


def _check(url: str) -> None:
    migrate.upgrade(url, "0011")
    ids = _run_sync(url, _seed)
    migrate.upgrade(url)
    after = _run_sync(url, _read)
    for name, (_, expected) in RUNS.items():
        assert after[ids[name]] == expected, name
    migrate.downgrade(url, "0011")
    back = _run_sync(
        url, lambda c: {r.id: (r.state, r.outcome, r.cause) for r in c.execute(sa.select(_RUNS))}
    )
    # the old words; an early return's cause stays on its run (the old fleet report counted the
    # causes of failed and aborted runs only, so it changes nothing there)
    for name, ((returned, cause), _) in RUNS.items():
        assert back[ids[name]] == ("completed", "completed", returned or cause or None), name
    migrate.upgrade(url)


@pytest.mark.slow
def test_sqlite_0012_rejudges_recorded_runs_both_ways():
    with tempfile.TemporaryDirectory() as tmp:
        _check(f"sqlite+aiosqlite:///{tmp}/m.db")


@pytest.mark.slow
def test_postgresql_0012_rejudges_recorded_runs_both_ways():
    _check(fresh_postgres("aerobase_migrations_0012"))
