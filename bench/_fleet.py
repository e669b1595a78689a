"""The assets' side of the load spread over several processes, for fleets one Python process cannot
drive (1,000 UAVs at 10 Hz is 10,000 sends and 10,000 acks a second).

Each helper process logs its slice of the assets in, opens their sockets, sends on the common
schedule (`pace` with a shared start: perf_counter is the system's monotonic clock) and reads their
acks. Send times, send counts and acked seqs go to shared memory, where the main process (which
holds the operators' sockets and times every delivery) reads them; the helpers report their send
lags, error replies and close codes when told to stop. The messages are the same pre-encoded
templates (`Payloads`) as in one process.
"""

from __future__ import annotations

import asyncio
import contextlib
import multiprocessing as mp
import time
from array import array
from dataclasses import dataclass, field
from multiprocessing.connection import Connection
from multiprocessing.shared_memory import SharedMemory
from typing import Any

from bench._load import Payloads, Recorder, pace


@dataclass
class Shared:
    """Shared-memory arrays: send time per (asset, seq % slots), messages sent, highest acked."""

    assets: int
    slots: int
    blocks: list[SharedMemory] = field(default_factory=list)
    owner: bool = False

    @classmethod
    def create(cls, assets: int, slots: int) -> Shared:
        """New zeroed arrays (the creating process unlinks them in `close`)."""
        shared = cls(assets, slots, owner=True)
        shared.blocks = [
            SharedMemory(create=True, size=8 * assets * slots),
            SharedMemory(create=True, size=8 * assets),
            SharedMemory(create=True, size=8 * assets),
        ]
        return shared

    @classmethod
    def attach(cls, assets: int, slots: int, names: list[str]) -> Shared:
        """The arrays another process created."""
        return cls(assets, slots, [SharedMemory(name=n) for n in names])

    @property
    def names(self) -> list[str]:
        """Names to attach with."""
        return [b.name for b in self.blocks]

    @property
    def sent_at(self) -> memoryview:
        """perf_counter of message seq of asset i at [i * slots + seq % slots]."""
        return self.blocks[0].buf.cast("d")

    @property
    def sent(self) -> memoryview:
        """Messages sent per asset (= the last seq)."""
        return self.blocks[1].buf.cast("q")

    @property
    def acked(self) -> memoryview:
        """The highest acked seq per asset."""
        return self.blocks[2].buf.cast("q")

    def close(self) -> None:
        """Detach (and unlink, in the creator)."""
        for b in self.blocks:
            b.close()
            if self.owner:
                with contextlib.suppress(FileNotFoundError):
                    b.unlink()


class SharedRecorder(Recorder):
    """A Recorder whose sends and acks happen in helper processes (read from shared memory)."""

    def __init__(self, assets: int, operators: int, shared: Shared) -> None:
        super().__init__(assets, operators)
        self.shared = shared
        self._sent_at = shared.sent_at
        self._sent = shared.sent
        self.acked = shared.acked  # type: ignore[assignment]

    def total_sent(self) -> int:
        """Messages sent so far, by every helper."""
        return sum(self._sent)

    def on_delivered(self, operator: int, asset: int, seq: int, t: float) -> None:
        """An operator received message `seq` of `asset` at perf_counter `t`."""
        self.delivered[operator] += 1
        if 0 < seq <= self._sent[asset]:
            t0 = self._sent_at[asset * self.shared.slots + seq % self.shared.slots]
            if self.window[0] <= t0 < self.window[1]:
                self.latencies.append(t - t0)

    def release(self) -> None:
        """Drop the views so the shared memory can be closed."""
        self._sent_at.release()
        self._sent.release()
        self.acked.release()  # type: ignore[attr-defined]


def slots_for(rate: float, warmup: float, seconds: float) -> int:
    """Send-time slots per asset: every seq of a run (plus slack) has its own."""
    return int(rate * (warmup + seconds + 2)) + 16


def _helper(
    conn: Connection,
    url: str,
    names: list[str],
    secrets: list[str],
    first: int,
    total: int,
    shm: list[str],
    slots: int,
    rate: float,
    warmup: float,
    seconds: float,
) -> None:
    """A helper process: connect its assets, wait for the start time, send, read acks, report."""
    import uvloop

    with asyncio.Runner(loop_factory=uvloop.new_event_loop) as runner:
        runner.run(
            _helper_main(conn, url, names, secrets, first, total, shm, slots, rate, warmup, seconds)
        )


async def _helper_main(
    conn: Connection,
    url: str,
    names: list[str],
    secrets: list[str],
    first: int,
    total: int,
    shm: list[str],
    slots: int,
    rate: float,
    warmup: float,
    seconds: float,
) -> None:
    import httpx

    from bench._aerobase import _asset, ack_reader, closed_codes

    shared = Shared.attach(total, slots, shm)
    sent_at, sent, acked = shared.sent_at, shared.sent, shared.acked
    n = len(names)
    payloads = Payloads(n)
    rec = Recorder(n, 0)
    errors = [0]
    async with httpx.AsyncClient(base_url=url, timeout=120) as api:
        sem = asyncio.Semaphore(8)

        async def open_one(i: int) -> Any:
            async with sem:
                for attempt in range(5):  # a server busy with 1,000 logins may ask for a retry
                    try:
                        return await _asset(
                            url, names[i], secrets[i], api, ack_reader(acked, first + i, errors)
                        )
                    except (OSError, RuntimeError, TimeoutError, httpx.HTTPError):
                        if attempt == 4:
                            raise
                        await asyncio.sleep(1 + attempt)
            return None

        sockets = await asyncio.gather(*(open_one(i) for i in range(n)))
    loop = asyncio.get_running_loop()
    conn.send(("connected", n))
    start = await loop.run_in_executor(None, conn.recv)

    def send(i: int, seq: int) -> None:
        g = first + i
        sent_at[g * slots + seq % slots] = rec.sent[i][seq - 1]
        sent[g] = seq
        # a socket the server closed stays counted as sent: its messages show up as lost
        sockets[i].send(payloads.text(i, seq))

    await pace(n, rate, warmup, seconds, rec, send, lambda _t: None, None, start, (first, total))
    await loop.run_in_executor(None, conn.recv)  # "stop", once the main process has drained
    closed = closed_codes(sockets)
    for ws in sockets:
        ws.close()
    conn.send(("done", list(rec.lags), errors[0], closed))
    for view in (sent_at, sent, acked):
        view.release()
    shared.close()


@dataclass
class Helpers:
    """The running helper processes and their pipes."""

    procs: list[Any]
    conns: list[Connection]

    def pids(self) -> list[int]:
        """Their process ids (for their CPU)."""
        return [p.pid for p in self.procs]

    def broadcast(self, message: Any) -> None:
        """Send to every helper."""
        for c in self.conns:
            c.send(message)

    def gather(self) -> list[Any]:
        """One message from every helper (blocking)."""
        return [c.recv() for c in self.conns]

    def stop(self) -> None:
        """End them (they exit on their own after reporting)."""
        for p in self.procs:
            p.join(10)
            if p.is_alive():
                p.terminate()


def start_helpers(
    procs: int,
    url: str,
    names: list[str],
    secrets: list[str],
    shared: Shared,
    rate: float,
    warmup: float,
    seconds: float,
) -> Helpers:
    """Start `procs` helper processes, each with a contiguous slice of the assets."""
    ctx = mp.get_context("spawn")
    n = len(names)
    bounds = [n * k // procs for k in range(procs + 1)]
    started, conns = [], []
    for k in range(procs):
        a, b = bounds[k], bounds[k + 1]
        mine, theirs = ctx.Pipe()
        p = ctx.Process(
            target=_helper,
            args=(
                theirs,
                url,
                names[a:b],
                secrets[a:b],
                a,
                n,
                shared.names,
                shared.slots,
                rate,
                warmup,
                seconds,
            ),
            daemon=True,
        )
        p.start()
        started.append(p)
        conns.append(mine)
    return Helpers(started, conns)


def merge_reports(reports: list[Any], rec: Recorder) -> dict[str, int]:
    """Fold the helpers' final reports into `rec`; returns the close codes they saw."""
    closed: dict[str, int] = {}
    for _, lags, errors, codes in reports:
        rec.lags.extend(array("d", lags))
        rec.errors += errors
        for code, count in codes.items():
            closed[code] = closed.get(code, 0) + count
    return closed


def now() -> float:
    """perf_counter (the clock every process shares)."""
    return time.perf_counter()
