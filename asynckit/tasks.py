"""Stopping background asyncio tasks so that a stop always ends.

`task.cancel(); await task` can hang on Python 3.11: `asyncio.wait_for` returns its inner result
when the inner future finishes at the very moment the outer task is cancelled (CPython gh-86296,
fixed in 3.12), so a loop built on `wait_for` — a poll loop, a reader — may never see the one
cancellation it was sent, and whoever awaits it waits forever. Under load the race is common.
`cancel_and_wait` cancels again until every task has ended.
"""

from __future__ import annotations

import asyncio
import logging
from collections.abc import Iterable
from typing import Any

log = logging.getLogger(__name__)


async def cancel_and_wait(
    tasks: Iterable[asyncio.Future[Any] | None], grace_s: float = 0.5, rounds: int = 40
) -> None:
    """Cancel `tasks` (None entries are skipped) and return once all have ended.

    A task still running `grace_s` after a cancellation is cancelled again, up to `rounds` times;
    one that outlives every round is logged as an error and left behind (a stop must not hang).
    What a task raised while ending is logged, not raised. A cancellation of the caller itself
    propagates as usual."""
    todo = [t for t in tasks if t is not None]
    pending = {t for t in todo if not t.done()}
    for attempt in range(rounds):
        if not pending:
            break
        if attempt:
            log.warning("%d task(s) ignored a cancellation; cancelling again", len(pending))
        for task in pending:
            task.cancel()
        _, pending = await asyncio.wait(pending, timeout=grace_s)
    for task in pending:
        log.error("task %r did not stop after %d cancellations", task, rounds)
    for task in todo:
        if task.done() and not task.cancelled() and task.exception() is not None:
            log.error("task %r ended with an error while stopping", task, exc_info=task.exception())
