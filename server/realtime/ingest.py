"""Durable storage of what assets send, in batches shared by every connection of this process.

A connection hands over (stream, seq, message); the batcher stores a batch in one transaction with
one commit: telemetry through the telemetry store (the SQL store joins the transaction: one
multi-row INSERT; InfluxDB is written first), events and stream positions (telemetry service: one
`UPDATE ... WHERE last_seq < seq` per stream, no objects loaded) and command results (commands
service). Then it tells each connection the highest seq of its own that is stored (`Acks.stored`,
once per batch, not per message), so acks are cumulative and cost no task wake-up per message.
Writes are idempotent (a replay after a crash stores nothing twice). The batcher waits at most
`max_delay_s` (0.25 s: a commit's cost is shared by more rows) after the first queued message,
or not at all once an event or command result waits (what a run reacts to), then takes up to
`max_batch` (bounded so that building one batch never holds the event loop for more than a few
milliseconds).

One bad row never fails a batch shared by many connections: a batch refused because of its data
(a value the database or the store cannot hold) is split in halves and retried until the rows at
fault are alone; each of those fails with `RowRejected` (its sender is answered `invalid_payload`)
and every other row is stored. Any other failure (the database unreachable, busy, a deadlock)
fails the batch as a whole: its senders are closed with 1011 and replay, so nothing is lost.
"""

from __future__ import annotations

import asyncio
import logging
import sqlite3
import time
import uuid
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field
from datetime import UTC, datetime
from typing import Any, Protocol

from sqlalchemy.exc import DataError, IntegrityError, StatementError
from sqlalchemy.ext.asyncio import AsyncSession, async_sessionmaker

from asynckit.tasks import cancel_and_wait
from server.commands import service as commands
from server.kit import metrics
from server.kit.db import sqlstate
from server.telemetry import service as telemetry
from server.telemetry.bulk import OneTrip
from server.telemetry.store import Sample, TelemetryStore

log = logging.getLogger(__name__)
DROPPED_EVENT = "telemetry_field_dropped"
# what a value the storage cannot hold raises: a replay would fail the same way
DATA_FAULTS = (
    DataError,
    IntegrityError,
    sqlite3.IntegrityError,  # the SQLite one-trip writer's own (a deleted asset's foreign key)
    sqlite3.DataError,
    ValueError,
    OverflowError,
    TypeError,
    UnicodeError,
)
# the queue length past which asset sockets stop being read (TCP pushes back to the assets, which
# keep their messages on disk), and below which they are read again
HIGH_WATER, LOW_WATER = 20_000, 5_000


def _data_fault(err: BaseException) -> bool:
    """True when the rows are at fault, not the database (a whitelist: anything else is replayed).

    Looks through the wrapped errors: SQLite's OverflowError and asyncpg's "invalid input for
    query argument" (a ValueError) are raised while binding parameters; PostgreSQL's own refusals
    carry SQLSTATE class 22 (data exception) or 23 (integrity constraint violation).
    """
    if sqlstate(err)[:2] in ("22", "23"):
        return True
    seen: BaseException | None = err
    for _ in range(5):
        if seen is None:
            return False
        if isinstance(seen, DATA_FAULTS):
            return True
        orig = seen.orig if isinstance(seen, StatementError) else None
        seen = orig if isinstance(orig, BaseException) else seen.__cause__
    return False


class RowRejected(Exception):
    """This one message cannot be stored (the rest of its batch was)."""


class Acks(Protocol):
    """What the ingest tells the connection a message came from, in the order it stored them."""

    def stored(self, seq: int) -> None:
        """Every message of this connection up to `seq` is stored (or was rejected)."""

    def rejected(self, seq: int, reason: str) -> None:
        """Message `seq` cannot be stored; the others of its batch were."""

    def failed(self, err: BaseException) -> None:
        """A batch holding messages of this connection failed as a whole (they are not stored)."""


@dataclass(slots=True)
class Item:
    """One message to store."""

    stream_id: uuid.UUID
    asset_id: uuid.UUID
    organization_id: uuid.UUID
    seq: int
    kind: str  # telemetry | event | command_result
    ts_ms: int
    payload: dict[str, Any]  # empty when `payload_json` carries it (UAV telemetry's fast path)
    re: uuid.UUID | None = None
    dropped: tuple[str, ...] = ()  # non-finite fields the server removed (recorded as an event)
    acks: Acks | None = None
    arrived: float = field(default_factory=time.monotonic)
    payload_json: str | None = None


def _ts(ms: int) -> datetime:
    return datetime.fromtimestamp(ms / 1000, UTC)


def _dropped_event(item: Item) -> dict[str, Any]:
    fields = ", ".join(item.dropped)
    return {
        "name": DROPPED_EVENT,
        "severity": "warning",
        "message": f"{item.kind} seq {item.seq}: non-finite numbers dropped ({fields})",
        "data": {"seq": item.seq, "kind": item.kind, "fields": list(item.dropped)},
    }


class Ingest:
    """The process-wide batcher."""

    def __init__(
        self,
        sessionmaker: async_sessionmaker[AsyncSession],
        store: TelemetryStore,
        max_batch: int = 2000,
        max_delay_s: float = 0.25,
        writer: async_sessionmaker[AsyncSession] | None = None,
        one_trip: OneTrip | None = None,
    ) -> None:
        """`writer` (default `sessionmaker`) stores the batches: a pool of its own keeps the
        ingest from waiting behind a thousand sockets' sweeps and heartbeats for a connection;
        `one_trip` (bulk.py), when given, stores a batch of nothing but telemetry in one trip."""
        self.sessionmaker = sessionmaker
        self.writer = writer or sessionmaker
        self.store = store
        self.max_batch = max_batch
        self.max_delay_s = max_delay_s
        self.one_trip = one_trip
        self._resume: list[Callable[[], None]] = []  # sockets paused while the queue was long
        self._due = asyncio.Event()  # the batch's wait is over
        self._urgent = False  # a message other than telemetry waits: store without waiting
        self.queue: deque[Item] = deque()
        self._ready = asyncio.Event()
        self._task: asyncio.Task[None] | None = None
        self.stored = 0

    def start(self) -> None:
        """Start the batcher task."""
        self._task = asyncio.create_task(self._run(), name="ingest")

    async def stop(self) -> None:
        """Store what is queued, then stop."""
        await cancel_and_wait([self._task])

    async def last_seq(self, stream_id: uuid.UUID, asset_id: uuid.UUID) -> int:
        """The highest stored seq of a stream (0 for a new stream); raises StreamOfAnotherAsset."""
        async with self.sessionmaker() as db:
            position = await telemetry.stream_position(db, stream_id, asset_id)
            await db.commit()
            return position

    def submit(self, item: Item) -> None:
        """Queue an item; `item.acks` hears once it is stored (or rejected, or failed)."""
        self.queue.append(item)
        self._ready.set()
        if item.kind != "telemetry" and not self._urgent:
            self._urgent = True
            self._due.set()

    @property
    def congested(self) -> bool:
        """The queue is past its high-water mark: stop reading what adds to it."""
        return len(self.queue) >= HIGH_WATER

    def resume_later(self, resume: Callable[[], None]) -> None:
        """Call `resume` once the queue is back under its low-water mark."""
        self._resume.append(resume)

    async def _run(self) -> None:
        loop = asyncio.get_running_loop()
        while True:
            await self._ready.wait()
            if len(self.queue) < self.max_batch and not self._urgent:
                # one timer per batch (not one per message): what arrives meanwhile joins it,
                # unless something other than telemetry comes (events, command results: what a
                # run waits for), which cuts the wait short
                self._due.clear()
                timer = loop.call_later(self.max_delay_s, self._due.set)
                await self._due.wait()
                timer.cancel()
            self._urgent = False
            n = min(len(self.queue), self.max_batch)
            batch = [self.queue.popleft() for _ in range(n)]
            if not self.queue:
                self._ready.clear()
            await self._store_isolated(batch)
            if self._resume and len(self.queue) <= LOW_WATER:
                resume, self._resume = self._resume, []
                for call in resume:
                    call()

    async def _store_isolated(self, batch: list[Item]) -> None:
        """Store a batch and tell its connections; a batch refused for its data is halved until
        the rows at fault are alone (only they fail); any other failure fails the batch
        (replayed)."""
        try:
            await self._store(batch)
        except asyncio.CancelledError:
            raise
        except Exception as err:
            if not _data_fault(err):
                log.exception("storing a batch of %d messages failed", len(batch))
                for acks in {id(i.acks): i.acks for i in batch if i.acks is not None}.values():
                    acks.failed(err)
                return
            if len(batch) == 1:
                item = batch[0]
                log.warning(
                    "message seq %d of asset %s cannot be stored: %r", item.seq, item.asset_id, err
                )
                if item.acks is not None:
                    item.acks.rejected(item.seq, f"message seq {item.seq} cannot be stored")
                return
            half = len(batch) // 2
            await self._store_isolated(batch[:half])
            await self._store_isolated(batch[half:])
            return
        highest: dict[int, tuple[Acks, int]] = {}
        for item in batch:
            if item.acks is not None:
                highest[id(item.acks)] = (item.acks, item.seq)  # a connection's items are in order
        for acks, seq in highest.values():
            acks.stored(seq)
        self.stored += len(batch)

    async def _store(self, batch: list[Item]) -> None:
        # the payload as it came (nested): flattened when read, not here, a thousand times a second
        samples = []
        highest: dict[uuid.UUID, int] = {}
        plain = True  # nothing but telemetry (no event, command result or dropped field)
        for i in batch:
            if i.seq > highest.get(i.stream_id, 0):  # not the last: a replay may follow the same
                highest[i.stream_id] = i.seq  # stream's items of a connection that just ended
            if i.kind == "telemetry":
                samples.append(Sample(i.asset_id, _ts(i.ts_ms), i.seq, i.payload, i.payload_json))
                plain = plain and not i.dropped
            else:
                plain = False
        if self.one_trip is not None and plain:
            if self.store.in_database:
                await self.one_trip.store(samples, highest)
            else:  # InfluxDB: durable when it answers, then the positions
                await self.store.write(samples)
                await self.one_trip.store((), highest)
            observe_stored(batch)
            return
        async with self.writer() as db:
            await self.store.write(samples, db)
            for item in batch:
                if item.kind == "event":
                    telemetry.record_event(
                        db, item.organization_id, item.asset_id, _ts(item.ts_ms), item.payload
                    )
                if item.dropped:
                    telemetry.record_event(
                        db,
                        item.organization_id,
                        item.asset_id,
                        _ts(item.ts_ms),
                        _dropped_event(item),
                    )
                elif item.kind == "command_result" and item.re is not None:
                    await commands.apply_result(db, item.re, item.asset_id, item.payload)
            await telemetry.advance_streams(db, highest)
            await db.commit()
        observe_stored(batch)


def observe_stored(batch: list[Item]) -> None:
    """The batch's ingest lag (of its oldest message: one observation per batch, not a histogram
    update per message), and what landing bases said of their PLC link and RTK."""
    if batch:
        metrics.INGEST_LAG.observe(time.monotonic() - min(item.arrived for item in batch))
    for item in batch:
        if item.kind == "telemetry" and "plc_link" in item.payload:
            asset = str(item.asset_id)
            metrics.BASE_PLC_LINK.labels(asset).set(item.payload["plc_link"] == "up")
            rtk = item.payload.get("rtk") or {}
            metrics.BASE_RTK_RATE.labels(asset).set(float(rtk.get("corrections_rate", 0.0)))
            if rtk.get("correction_age_s") is not None:
                metrics.BASE_RTK_AGE.labels(asset).set(float(rtk["correction_age_s"]))
