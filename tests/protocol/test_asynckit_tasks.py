"""cancel_and_wait: a stop always ends, even for a task that lost its cancellation."""

from __future__ import annotations

import asyncio
import logging

from asynckit.tasks import cancel_and_wait


async def _deaf_loop(swallow: int, ticks: list[int]) -> None:
    """A loop that loses its first `swallow` cancellations, as a loop on 3.11's wait_for can."""
    lost = 0
    while True:
        try:
            await asyncio.sleep(0.01)
            ticks.append(1)
        except asyncio.CancelledError:
            if lost >= swallow:
                raise
            lost += 1


async def test_a_task_that_swallows_cancellations_is_cancelled_again_until_it_ends(caplog):
    ticks: list[int] = []
    task = asyncio.ensure_future(_deaf_loop(2, ticks))
    await asyncio.sleep(0.03)
    with caplog.at_level(logging.WARNING, logger="asynckit.tasks"):
        await asyncio.wait_for(cancel_and_wait([task], grace_s=0.05), 5)
    assert task.cancelled()
    assert sum("cancelling again" in r.message for r in caplog.records) == 2


async def test_plain_tasks_none_entries_and_finished_ones_are_fine():
    done = asyncio.ensure_future(asyncio.sleep(0))
    await done
    sleeper = asyncio.ensure_future(asyncio.sleep(60))
    await cancel_and_wait([None, done, sleeper])
    assert sleeper.cancelled() and done.done() and not done.cancelled()


async def test_an_error_raised_while_stopping_is_logged_not_raised(caplog):
    async def fails_on_cancel() -> None:
        try:
            await asyncio.sleep(60)
        except asyncio.CancelledError:
            raise RuntimeError("flush failed") from None

    task = asyncio.ensure_future(fails_on_cancel())
    await asyncio.sleep(0)
    with caplog.at_level(logging.ERROR, logger="asynckit.tasks"):
        await cancel_and_wait([task])
    assert any("ended with an error" in r.message for r in caplog.records)


async def test_a_task_that_never_stops_is_left_behind_after_its_rounds(caplog):
    released = asyncio.Event()

    async def immortal() -> None:
        while not released.is_set():
            try:
                await asyncio.sleep(60)
            except asyncio.CancelledError:
                continue

    task = asyncio.ensure_future(immortal())
    await asyncio.sleep(0)
    with caplog.at_level(logging.ERROR, logger="asynckit.tasks"):
        await asyncio.wait_for(cancel_and_wait([task], grace_s=0.01, rounds=3), 5)
    assert not task.done()
    assert any("did not stop after 3 cancellations" in r.message for r in caplog.records)
    released.set()  # now let it end, so nothing is left running
    task.cancel()
    await asyncio.wait([task], timeout=5)
    assert task.done()
