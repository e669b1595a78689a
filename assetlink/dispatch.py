"""Inbound commands: run each id once, answer redeliveries from the ledger.

Before a handler runs, the command's `(name, params)` is parsed into its typed model from
`protocol.vocabulary`: params that do not fit are answered `rejected` naming the field, so a
handler only ever sees a valid `CommandRequest[Model]`.

A handler is an async function taking a `CommandRequest` and either returning a final
`CommandResultPayload` (or None for plain success), or an async generator that yields
`CommandProgress` values (sent as in_progress results) and finally a final result.
An exception becomes a `failed` result. Every result goes through the outbox, recorded in
the same transaction as the ledger, so none is lost and none is produced twice.
"""

from __future__ import annotations

import asyncio
import logging
import uuid
from collections.abc import AsyncIterator, Awaitable, Callable
from dataclasses import dataclass
from typing import Any, Generic, TypeVar

from pydantic import ValidationError

from assetlink.outbox import AsyncOutbox
from asynckit.tasks import cancel_and_wait
from protocol import vocabulary
from protocol.messages import Command, CommandProgress, CommandResultPayload, now_ms
from protocol.vocabulary import CommandParams, CommandStatus

log = logging.getLogger(__name__)

HandlerOutput = (
    AsyncIterator[CommandProgress | CommandResultPayload] | Awaitable[CommandResultPayload | None]
)


C = TypeVar("C", bound=CommandParams, covariant=True)


@dataclass(frozen=True, slots=True)
class CommandRequest(Generic[C]):
    """One command for a handler: its id, the typed command and its deadline (unix ms)."""

    id: uuid.UUID
    command: C
    deadline: int = 0

    @property
    def name(self) -> str:
        """The command's name on the wire."""
        return self.command.name

    def remaining_s(self) -> float:
        """Seconds left before the deadline (negative once past it)."""
        return (self.deadline - now_ms()) / 1000


Handler = Callable[[CommandRequest[Any]], HandlerOutput]


def result(
    status: CommandStatus, reason: str = "", data: dict[str, Any] | None = None
) -> CommandResultPayload:
    """Shorthand for a command result."""
    return CommandResultPayload(status=status, reason=reason, data=data)


@dataclass(slots=True)
class CommandStats:
    """Counters of the dispatcher."""

    executed: int = 0
    redelivered: int = 0
    rejected: int = 0


class CommandDispatcher:
    """Routes commands to handlers by name, once per command id."""

    def __init__(self, outbox: AsyncOutbox, queued: Callable[[], None] = lambda: None):
        """Record results in `outbox`; call `queued()` after each result is queued."""
        self._outbox = outbox
        self.queued = queued
        self._handlers: dict[str, Handler] = {}
        self._tasks: dict[str, asyncio.Task[None]] = {}
        self.stats = CommandStats()

    def register(self, command: type[CommandParams] | str, handler: Handler) -> None:
        """Run `handler` for this command of the vocabulary (replacing any previous one)."""
        name = command if isinstance(command, str) else command.name
        if name not in vocabulary.COMMANDS:
            raise ValueError(f"{name!r} is not a command of protocol.vocabulary")
        self._handlers[name] = handler

    @property
    def running(self) -> frozenset[str]:
        """Ids of the commands executing in this process."""
        return frozenset(self._tasks)

    async def recover(self) -> int:
        """Fail the commands a previous process left running; returns how many."""
        interrupted = await self._outbox.running_commands()
        for record in interrupted:
            log.warning("command %s (%s) was interrupted by a restart", record.id, record.name)
            await self._finish(record.id, result("failed", "interrupted: the agent restarted"))
        return len(interrupted)

    async def handle(self, command: Command) -> None:
        """Start a new command, or answer a redelivered one without running it again."""
        cid, name = str(command.id), command.payload.name
        known = await self._outbox.begin_command(cid, name)
        if known is not None:
            self.stats.redelivered += 1
            if known.state == "done" and known.result is not None:
                log.info("command %s redelivered: answering its first result", cid)
                await self._requeue(cid, known.result)
            elif cid in self._tasks:
                log.info("command %s redelivered while running: answering in_progress", cid)
                await self._requeue(cid, known.progress or _still_running().model_dump_json())
            else:
                await self._finish(cid, result("failed", "interrupted: the agent restarted"))
            return
        handler = self._handlers.get(name)
        if handler is None:
            self.stats.rejected += 1
            await self._finish(cid, result("rejected", f"unknown command {name!r}"))
            return
        if command.payload.deadline and command.payload.deadline < now_ms():
            self.stats.rejected += 1
            await self._finish(cid, result("timed_out", "the deadline passed before it started"))
            return
        try:
            typed = vocabulary.parse(name, command.payload.params)
        except ValidationError as err:
            self.stats.rejected += 1
            reason = f"invalid params for {name}: {vocabulary.describe(err)}"
            await self._finish(cid, result("rejected", reason))
            return
        request = CommandRequest(command.id, typed, command.payload.deadline)
        self.stats.executed += 1
        task = asyncio.create_task(self._run(handler, request), name=f"command-{name}-{cid}")
        self._tasks[cid] = task
        task.add_done_callback(lambda _t: self._tasks.pop(cid, None))

    async def stop(self) -> None:
        """Cancel running commands; each records a `canceled` result."""
        await cancel_and_wait(list(self._tasks.values()))

    async def _run(self, handler: Handler, request: CommandRequest[Any]) -> None:
        cid = str(request.id)
        try:
            final = await self._drive(handler, request)
        except asyncio.CancelledError:
            await self._finish(cid, result("canceled", "the agent is stopping"))
            raise
        except Exception as err:
            log.exception("command %s (%s) failed", cid, request.name)
            final = result("failed", f"{type(err).__name__}: {err}")
        await self._finish(cid, final)

    async def _drive(self, handler: Handler, request: CommandRequest[Any]) -> CommandResultPayload:
        output = handler(request)
        if not hasattr(output, "__aiter__"):
            value = await output  # type: ignore[misc]
            return _final(value)
        stream: AsyncIterator[Any] = output  # type: ignore[assignment]
        try:
            async for item in stream:
                if isinstance(item, CommandResultPayload) and item.final:
                    return item
                await self._progress(request.id, item)
        finally:
            aclose = getattr(stream, "aclose", None)
            if aclose is not None:
                await aclose()
        return result("succeeded")

    async def _progress(self, cid: uuid.UUID, item: Any) -> None:
        if isinstance(item, CommandProgress):
            item = CommandResultPayload(status="in_progress", progress=item)
        if not isinstance(item, CommandResultPayload):
            raise TypeError(f"a handler yielded {type(item).__name__}, not a progress or result")
        await self._outbox.progress_command(str(cid), item.model_dump_json())
        self.queued()

    async def _finish(self, cid: str, final: CommandResultPayload) -> None:
        if not final.final:
            final = result("failed", f"handler ended with non-final status {final.status!r}")
        if await self._outbox.finish_command(cid, final.model_dump_json()):
            self.queued()

    async def _requeue(self, cid: str, payload: str) -> None:
        await self._outbox.append("command_result", payload, re=cid)
        self.queued()


def _final(value: Any) -> CommandResultPayload:
    if value is None:
        return result("succeeded")
    if isinstance(value, CommandResultPayload):
        return value
    raise TypeError(f"a handler returned {type(value).__name__}, not a CommandResultPayload")


def _still_running() -> CommandResultPayload:
    return CommandResultPayload(status="in_progress", reason="already running")
