"""The one way tests wait for something that happens elsewhere: poll a predicate, fail with what
was awaited. Used instead of sleeps standing in for synchronisation."""

from __future__ import annotations

import asyncio
import inspect
import time
from collections.abc import Awaitable, Callable
from typing import Any

Predicate = Callable[[], Any | Awaitable[Any]]


async def eventually(
    predicate: Predicate, within: float = 10.0, what: str = "", interval: float = 0.01
) -> Any:
    """Poll `predicate` (plain or async) until it returns a truthy value, and return that value;
    fail the test after `within` wall seconds, naming `what` was awaited."""
    deadline = time.monotonic() + within
    while True:
        value = predicate()
        if inspect.isawaitable(value):
            value = await value
        if value:
            return value
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out after {within} s waiting for {what or 'condition'}")
        await asyncio.sleep(interval)


def wait_for(
    predicate: Callable[[], Any], within: float = 10.0, what: str = "", interval: float = 0.02
) -> Any:
    """`eventually` for code outside an event loop (threads, subprocesses)."""
    deadline = time.monotonic() + within
    while True:
        value = predicate()
        if value:
            return value
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out after {within} s waiting for {what or 'condition'}")
        time.sleep(interval)
