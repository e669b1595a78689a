"""Shared helpers for the simulator tests: a condition waiter and a running world."""

from __future__ import annotations

import asyncio
import inspect
import time
from collections.abc import AsyncIterator, Awaitable, Callable

import pytest

from sim.world import World, WorldConfig


async def wait_until(
    predicate: Callable[[], bool | Awaitable[bool]], within: float = 10.0, what: str = ""
) -> None:
    """Poll `predicate` until it holds; fail the test after `within` wall seconds."""
    deadline = time.monotonic() + within
    while True:
        result = predicate()
        if inspect.isawaitable(result):
            result = await result
        if result:
            return
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out after {within}s waiting for {what or predicate}")
        await asyncio.sleep(0.01)


@pytest.fixture
def waiter() -> Callable[..., Awaitable[None]]:
    """The `wait_until` helper as a fixture."""
    return wait_until


@pytest.fixture
async def world() -> AsyncIterator[World]:
    """A world at 20x speed on free ports."""
    async with World(WorldConfig.for_tests(speed=20.0, seed=7)) as w:
        yield w
