"""The link's on-disk state: a bounded outbox of durable messages, seq numbering,
the session token and the command ledger, in one SQLite file (`statefile.StateFile`).

`Outbox` is synchronous and owned by one thread; `AsyncOutbox` runs it on a dedicated
worker thread so the event loop never waits on the disk.

Seq numbers are handed out when an entry is first taken for sending, not when it is
queued: entries dropped at the bound never had a seq, so the server's contiguous ack
never stalls on a gap. After a reconnect the server's `last_acked_seq` is authoritative:
entries at or below it are deleted and the rest are renumbered from it, in order.
"""

from __future__ import annotations

import asyncio
import json
import logging
import uuid
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import Any, TypeVar

from assetlink.statefile import StateFile
from protocol.messages import EventPayload, now_ms

log = logging.getLogger(__name__)
T = TypeVar("T")


@dataclass(frozen=True, slots=True)
class Pending:
    """One outbox entry taken for sending, with its seq and its envelope's JSON text."""

    pos: int
    seq: int
    type: str
    text: str


@dataclass(frozen=True, slots=True)
class CommandRecord:
    """What the ledger knows of a command: running (last progress) or done (first result)."""

    id: str
    name: str
    state: str
    progress: str | None
    result: str | None


@dataclass(frozen=True, slots=True)
class Token:
    """A persisted session token and its expiry (unix seconds)."""

    access_token: str
    expires_at: float


def _envelope_text(id: str, seq: int, ts: int, re: str | None, type: str, payload: str) -> str:
    re_part = "" if re is None else f',"re":{json.dumps(re)}'
    return (
        f'{{"v":1,"id":{json.dumps(id)},"seq":{seq},"ts":{ts}{re_part},'
        f'"type":{json.dumps(type)},"payload":{payload}}}'
    )


class Outbox(StateFile):
    """Synchronous SQLite state of one link; use from a single thread."""

    def __init__(self, path: str | Path, max_entries: int = 100_000, synchronous: str = "NORMAL"):
        """Open (or create) the state file at `path`, keeping at most `max_entries` queued."""
        if max_entries < 1:
            raise ValueError("max_entries must be at least 1")
        super().__init__(path, synchronous)
        self.max_entries = max_entries
        with self._tx():
            if self._meta("stream_id") is None:
                self._set("stream_id", str(uuid.uuid4()))
            if self._meta("next_seq") is None:
                self._set("next_seq", "1")
        self._count = self._db.execute("SELECT COUNT(*) FROM outbox").fetchone()[0]

    # --- identity and counters ---

    @property
    def stream_id(self) -> uuid.UUID:
        """This sender's durable stream id (created once, kept forever)."""
        return uuid.UUID(self._meta("stream_id"))

    @property
    def next_seq(self) -> int:
        """The seq the next entry taken for sending will get."""
        return int(self._meta("next_seq") or 1)

    def __len__(self) -> int:
        """How many entries are queued (sent or not) and not yet acked."""
        return self._count

    def dropped_total(self) -> int:
        """How many entries were ever dropped at the bound."""
        return int(self._meta("dropped_total") or 0)

    def dropped_unreported(self) -> int:
        """How many drops have not been reported to the server yet."""
        return int(self._meta("dropped_unreported") or 0)

    def in_flight(self) -> int:
        """How many entries have a seq (were sent this session) and await their ack."""
        return self._db.execute("SELECT COUNT(*) FROM outbox WHERE seq IS NOT NULL").fetchone()[0]

    def last_pos(self) -> int:
        """The position of the newest entry (0 when empty)."""
        return self._db.execute("SELECT COALESCE(MAX(pos), 0) FROM outbox").fetchone()[0]

    def first_pos(self) -> int:
        """The position of the oldest entry not yet acked (0 when empty)."""
        return self._db.execute("SELECT COALESCE(MIN(pos), 0) FROM outbox").fetchone()[0]

    # --- the queue ---

    def append(
        self,
        type: str,
        payload: str,
        *,
        re: str | None = None,
        id: str | None = None,
        ts: int | None = None,
    ) -> int:
        """Queue one message (payload as JSON text); drop the oldest when full. Returns drops."""
        with self._tx():
            dropped = self._append(type, payload, re, id, ts)
        return dropped

    def _append(
        self, type: str, payload: str, re: str | None, id: str | None, ts: int | None
    ) -> int:
        dropped = self._make_room()
        self._db.execute(
            "INSERT INTO outbox (id, type, ts, re, payload) VALUES (?, ?, ?, ?, ?)",
            (id or str(uuid.uuid4()), type, now_ms() if ts is None else ts, re, payload),
        )
        self._count += 1
        return dropped

    def _make_room(self) -> int:
        """Drop the oldest entries so one more fits; count them as unreported drops."""
        excess = self._count + 1 - self.max_entries
        if excess <= 0:
            return 0
        dropped = self._db.execute(
            "DELETE FROM outbox WHERE pos IN (SELECT pos FROM outbox ORDER BY pos LIMIT ?)",
            (excess,),
        ).rowcount
        self._bump("dropped_total", dropped)
        self._bump("dropped_unreported", dropped)
        self._count -= dropped
        return dropped

    def take(self, limit: int) -> list[Pending]:
        """Number the next `limit` unsent entries, in queue order, and return them to send."""
        with self._tx():
            rows = self._db.execute(
                "SELECT pos, id, ts, re, type, payload FROM outbox WHERE seq IS NULL "
                "ORDER BY pos LIMIT ?",
                (limit,),
            ).fetchall()
            seq = self.next_seq
            taken = []
            for pos, id_, ts, re, type_, payload in rows:
                self._db.execute("UPDATE outbox SET seq = ? WHERE pos = ?", (seq, pos))
                taken.append(
                    Pending(pos, seq, type_, _envelope_text(id_, seq, ts, re, type_, payload))
                )
                seq += 1
            if taken:
                self._set("next_seq", str(seq))
        return taken

    def ack(self, seq: int) -> int:
        """Delete every entry the server has stored (seq <= `seq`); returns how many."""
        with self._tx():
            n = self._db.execute(
                "DELETE FROM outbox WHERE seq IS NOT NULL AND seq <= ?", (seq,)
            ).rowcount
        self._count -= n
        return n

    def resume(self, last_acked_seq: int) -> tuple[int, int]:
        """Start a session from the server's last ack: drop what it has, renumber the rest.

        Returns (entries the server already had, entries left to send).
        """
        with self._tx():
            n = self._db.execute(
                "DELETE FROM outbox WHERE seq IS NOT NULL AND seq <= ?", (last_acked_seq,)
            ).rowcount
            self._db.execute("UPDATE outbox SET seq = NULL WHERE seq IS NOT NULL")
            self._set("next_seq", str(last_acked_seq + 1))
        self._count -= n
        return n, self._count

    def report_drops(self) -> int:
        """Queue one `outbox_overflow` event for unreported drops; returns the count reported."""
        with self._tx():
            if self.dropped_unreported():
                self._make_room()  # counted in this very report
            n = self.dropped_unreported()
            if n:
                event = EventPayload(
                    name="outbox_overflow",
                    severity="warning",
                    message=f"{n} queued messages were dropped (oldest first) at the outbox bound",
                    data={"dropped": n, "dropped_total": self.dropped_total(),
                          "max_entries": self.max_entries},
                )  # fmt: skip
                self._set("dropped_unreported", "0")
                self._append("event", event.model_dump_json(), None, None, None)
        return n

    # --- the token ---

    def load_token(self) -> Token | None:
        """The persisted session token, if any."""
        raw = self._meta("token")
        return None if raw is None else Token(**json.loads(raw))

    def save_token(self, token: Token | None) -> None:
        """Persist (or with None, forget) the session token."""
        with self._tx():
            if token is None:
                self._db.execute("DELETE FROM meta WHERE key = 'token'")
            else:
                self._set("token", json.dumps({"access_token": token.access_token,
                                               "expires_at": token.expires_at}))  # fmt: skip

    # --- the command ledger ---

    def command(self, command_id: str) -> CommandRecord | None:
        """What the ledger holds for a command id."""
        row = self._db.execute(
            "SELECT id, name, state, progress, result FROM commands WHERE id = ?", (command_id,)
        ).fetchone()
        return None if row is None else CommandRecord(*row)

    def begin_command(self, command_id: str, name: str) -> CommandRecord | None:
        """Record a new command as running; if the id is known, return its record instead."""
        with self._tx():
            known = self.command(command_id)
            if known is None:
                self._db.execute(
                    "INSERT INTO commands (id, name, received_ms, state) VALUES (?, ?, ?, 'running')",
                    (command_id, name, now_ms()),
                )
        return known

    def progress_command(self, command_id: str, result: str) -> None:
        """Record an in_progress result and queue it, atomically."""
        with self._tx():
            self._db.execute(
                "UPDATE commands SET progress = ? WHERE id = ? AND state = 'running'",
                (result, command_id),
            )
            self._append("command_result", result, command_id, None, None)

    def finish_command(self, command_id: str, result: str) -> bool:
        """Record the final result and queue it, atomically; False if it already had one."""
        with self._tx():
            done = self._db.execute(
                "UPDATE commands SET state = 'done', result = ? WHERE id = ? AND state = 'running'",
                (result, command_id),
            ).rowcount
            if done:
                self._append("command_result", result, command_id, None, None)
        return bool(done)

    def running_commands(self) -> list[CommandRecord]:
        """Commands recorded as running (after a restart: interrupted ones)."""
        rows = self._db.execute(
            "SELECT id, name, state, progress, result FROM commands WHERE state = 'running'"
        ).fetchall()
        return [CommandRecord(*row) for row in rows]

    def prune_commands(self, older_than_ms: int) -> int:
        """Forget finished commands received before `older_than_ms`; returns how many."""
        with self._tx():
            return self._db.execute(
                "DELETE FROM commands WHERE state = 'done' AND received_ms < ?", (older_than_ms,)
            ).rowcount


class AsyncOutbox:
    """An `Outbox` on its own worker thread, awaited from the event loop."""

    def __init__(self, outbox: Outbox, executor: ThreadPoolExecutor):
        """Wrap an outbox already opened on `executor`'s single thread."""
        self.sync = outbox
        self._executor = executor

    @classmethod
    async def open(cls, path: str | Path, max_entries: int = 100_000, **kw: Any) -> AsyncOutbox:
        """Open the state file on a fresh worker thread."""
        executor = ThreadPoolExecutor(max_workers=1, thread_name_prefix="outbox")
        loop = asyncio.get_running_loop()
        try:
            outbox = await loop.run_in_executor(executor, lambda: Outbox(path, max_entries, **kw))
        except BaseException:
            executor.shutdown(wait=False)
            raise
        return cls(outbox, executor)

    async def call(self, fn: Callable[..., T], *args: Any) -> T:
        """Run `fn(*args)` on the outbox's thread."""
        return await asyncio.get_running_loop().run_in_executor(self._executor, fn, *args)

    def __getattr__(self, name: str) -> Callable[..., Any]:
        target = getattr(self.sync, name)
        if not callable(target):
            raise AttributeError(name)

        async def run(*args: Any, **kw: Any) -> Any:
            return await self.call(lambda: target(*args, **kw))

        return run

    async def close(self) -> None:
        """Close the database and stop the worker thread."""
        await self.call(self.sync.close)
        self._executor.shutdown(wait=True)
