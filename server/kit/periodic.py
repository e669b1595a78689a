"""A background task that calls an async function every few seconds, logging (not dying of) errors."""

from __future__ import annotations

import asyncio
import logging
from collections.abc import Awaitable, Callable

from asynckit.tasks import cancel_and_wait

log = logging.getLogger(__name__)


class Periodic:
    """Runs `tick()` every `every_s` seconds from `start()` until `stop()`; with `idle_s`, a tick
    that returns False (it found nothing to do) is followed by `idle_s` instead."""

    def __init__(
        self,
        name: str,
        tick: Callable[[], Awaitable[bool | None]],
        every_s: float,
        idle_s: float | None = None,
    ) -> None:
        self.name = name
        self.tick = tick
        self.every_s = every_s
        self.idle_s = idle_s
        self._task: asyncio.Task[None] | None = None

    def start(self) -> None:
        """Start the loop."""
        self._task = asyncio.create_task(self._loop(), name=self.name)

    async def stop(self) -> None:
        """Stop the loop."""
        await cancel_and_wait([self._task])

    async def _loop(self) -> None:
        while True:
            busy: bool | None = True
            try:
                busy = await self.tick()
            except asyncio.CancelledError:
                raise
            except Exception:
                log.exception("%s: tick failed", self.name)
            idle = busy is False and self.idle_s is not None
            await asyncio.sleep(self.idle_s if idle and self.idle_s is not None else self.every_s)
