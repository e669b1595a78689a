"""Shared helpers for the simulator tests: a condition waiter and a running world."""

from __future__ import annotations

from collections.abc import AsyncIterator, Awaitable, Callable

import pytest

from sim.world import World, WorldConfig
from tests.polling import eventually


@pytest.fixture
def waiter() -> Callable[..., Awaitable[None]]:
    """The `eventually` helper as a fixture."""
    return eventually


@pytest.fixture
async def world() -> AsyncIterator[World]:
    """A world at 20x speed on free ports."""
    async with World(WorldConfig.for_tests(speed=20.0, seed=7)) as w:
        yield w
