"""The unit of work on the real database: hooks and session-end listeners run only after a
successful commit, never after a rollback, and a failing hook does not undo the commit."""

from __future__ import annotations

import uuid

import pytest
from sqlalchemy import select

from server.kit.db import make_engine, make_sessionmaker
from server.kit.uow import unit_of_work
from server.organizations.models import Organization


@pytest.fixture
async def sessionmaker(database_url: str):  # type: ignore[no-untyped-def]
    engine = make_engine(database_url)
    yield make_sessionmaker(engine)
    await engine.dispose()


async def _exists(sessionmaker, name: str) -> bool:  # type: ignore[no-untyped-def]
    async with sessionmaker() as db:
        stmt = select(Organization).where(Organization.name == name)
        return (await db.execute(stmt)).scalar_one_or_none() is not None


async def test_hooks_run_after_the_commit_and_see_its_rows(sessionmaker):  # type: ignore[no-untyped-def]
    name, seen, ended = f"uow-{uuid.uuid4().hex[:8]}", [], []
    session_id = uuid.uuid4()

    async def listener(ids: list[uuid.UUID], reason: str) -> None:
        ended.append((ids, reason))

    async def hook() -> None:
        seen.append(await _exists(sessionmaker, name))  # from another connection: committed

    async with unit_of_work(sessionmaker, session_end_listeners=(listener,)) as uow:
        uow.db.add(Organization(name=name))
        uow.after_commit(hook)
        uow.sessions_ended([session_id], "logged out")
        await uow.db.flush()
        assert seen == [] and ended == []
    assert seen == [True]
    assert ended == [([session_id], "logged out")]


async def test_a_rollback_runs_no_hook(sessionmaker):  # type: ignore[no-untyped-def]
    name, ran = f"uow-{uuid.uuid4().hex[:8]}", []

    async def hook() -> None:
        ran.append(True)

    async def listener(ids: list[uuid.UUID], reason: str) -> None:
        ran.append(True)

    with pytest.raises(RuntimeError):
        async with unit_of_work(sessionmaker, session_end_listeners=(listener,)) as uow:
            uow.db.add(Organization(name=name))
            uow.after_commit(hook)
            uow.sessions_ended([uuid.uuid4()], "disabled")
            await uow.db.flush()
            raise RuntimeError("the endpoint failed")
    assert ran == []
    assert not await _exists(sessionmaker, name)


async def test_a_failing_hook_leaves_the_commit_and_the_other_hooks(sessionmaker):  # type: ignore[no-untyped-def]
    name, ran = f"uow-{uuid.uuid4().hex[:8]}", []

    async def broken() -> None:
        raise ConnectionError("broker down")

    async def fine() -> None:
        ran.append(True)

    async with unit_of_work(sessionmaker) as uow:
        uow.db.add(Organization(name=name))
        uow.after_commit(broken)
        uow.after_commit(fine)
    assert ran == [True]
    assert await _exists(sessionmaker, name)
