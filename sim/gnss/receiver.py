"""The simulated GNSS base receiver: streams its RTCM3 epochs over TCP to every client."""

from __future__ import annotations

import asyncio
import contextlib
import logging
import math
import random
from collections.abc import AsyncIterator
from dataclasses import dataclass

from pydantic import BaseModel, ConfigDict, Field

from asynckit.tasks import cancel_and_wait
from sim.clock import SimClock
from sim.gnss.station import BaseStationModel, GnssConfig

log = logging.getLogger(__name__)

MAX_CLIENT_BACKLOG = 1 << 20  # a client that falls this far behind is dropped


class GnssFaults(BaseModel):
    """Fault switches: stop streaming, garbage before each epoch, corrupted frames."""

    model_config = ConfigDict(frozen=True)

    streaming: bool = True
    garbage_bytes: int = Field(
        default=0, ge=0, le=4096, description="random bytes sent before each epoch"
    )
    corrupt_fraction: float = Field(
        default=0.0, ge=0.0, le=1.0, description="share of frames with a bit flipped"
    )


@dataclass
class ClientStats:
    """What the receiver has sent one connected client."""

    peer: str
    epochs: int = 0
    frames_sent: int = 0
    frames_corrupted: int = 0
    garbage_bytes: int = 0
    bytes_sent: int = 0


@dataclass
class _Client:
    stats: ClientStats
    writer: asyncio.StreamWriter


def corrupt_frame(frame: bytes, rng: random.Random) -> bytes:
    """Flip one bit past the frame header (payload or CRC), so the length survives but CRC fails."""
    data = bytearray(frame)
    index = rng.randrange(3, len(data))
    data[index] ^= 1 << rng.randrange(8)
    return bytes(data)


class GnssReceiver:
    """A base receiver sending one RTCM3 epoch per simulated second to any number of TCP clients."""

    def __init__(self, config: GnssConfig | None = None, clock: SimClock | None = None) -> None:
        self.config = config or GnssConfig()
        self.model = BaseStationModel(self.config)
        self.clock = clock or SimClock()
        self.faults = GnssFaults()
        self.epochs_sent = 0
        self.last_epoch: int | None = None
        self._fault_rng = random.Random(f"faults:{self.config.seed}")
        self._clients: list[_Client] = []
        self._server: asyncio.Server | None = None
        self._task: asyncio.Task[None] | None = None
        self._handlers: set[asyncio.Task[None]] = set()

    @property
    def port(self) -> int:
        """The TCP port the receiver listens on (after start)."""
        if self._server is None:
            raise RuntimeError("receiver not started")
        return self._server.sockets[0].getsockname()[1]

    @property
    def clients(self) -> list[ClientStats]:
        """Statistics of the currently connected clients."""
        return [c.stats for c in self._clients]

    def set_faults(self, **changes: object) -> GnssFaults:
        """Change some fault switches; returns the new set."""
        self.faults = GnssFaults.model_validate({**self.faults.model_dump(), **changes})
        log.info("gnss faults now %s", self.faults.model_dump())
        return self.faults

    async def start(self, host: str = "127.0.0.1", port: int = 5021) -> None:
        """Listen on host:port (0 = a free port) and start the 1 Hz epoch loop."""
        self._server = await asyncio.start_server(self._on_client, host, port)
        self._task = asyncio.create_task(self._run(), name="gnss-epochs")
        log.info("gnss receiver streaming RTCM3 on %s:%d", host, self.port)

    async def stop(self) -> None:
        """Stop streaming, close every client and stop listening."""
        await cancel_and_wait([self._task])
        self._task = None
        if self._server is not None:
            self._server.close()
        await self.disconnect_clients()
        await cancel_and_wait(list(self._handlers))
        if self._server is not None:
            await self._server.wait_closed()
            self._server = None

    async def disconnect_clients(self) -> int:
        """Drop every connected client (they may reconnect); returns how many were dropped."""
        clients, self._clients = self._clients, []
        for c in clients:
            c.writer.close()
        for c in clients:
            with contextlib.suppress(OSError, ConnectionError):
                await c.writer.wait_closed()
        return len(clients)

    async def _on_client(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        task = asyncio.current_task()
        if task is not None:
            self._handlers.add(task)
        peer = writer.get_extra_info("peername")
        client = _Client(ClientStats(peer=f"{peer[0]}:{peer[1]}" if peer else "?"), writer)
        self._clients.append(client)
        log.info("gnss client %s connected", client.stats.peer)
        try:
            while await reader.read(1024):
                pass  # clients have nothing to say to a base receiver; ignore it
        except (OSError, ConnectionError):
            pass
        finally:
            if client in self._clients:
                self._clients.remove(client)
            writer.close()
            log.info("gnss client %s disconnected", client.stats.peer)
            if task is not None:
                self._handlers.discard(task)

    async def _run(self) -> None:
        epoch = math.ceil(self.clock.now())
        while True:
            await self.clock.sleep(epoch - self.clock.now())
            if self.faults.streaming:
                self._broadcast(epoch)
            behind = math.floor(self.clock.now()) - epoch
            if behind > 2:
                log.warning("gnss receiver %d epochs behind; skipping ahead", behind)
                epoch += behind
            epoch += 1

    def _broadcast(self, epoch: int) -> None:
        frames = self.model.frames(epoch)
        self.epochs_sent += 1
        self.last_epoch = epoch
        faults = self.faults
        for client in list(self._clients):
            if client.writer.is_closing():
                continue
            stats = client.stats
            parts = []
            if faults.garbage_bytes:
                parts.append(self._fault_rng.randbytes(faults.garbage_bytes))
                stats.garbage_bytes += faults.garbage_bytes
            for frame in frames:
                if faults.corrupt_fraction and self._fault_rng.random() < faults.corrupt_fraction:
                    frame = corrupt_frame(frame, self._fault_rng)
                    stats.frames_corrupted += 1
                parts.append(frame)
            data = b"".join(parts)
            client.writer.write(data)
            stats.epochs += 1
            stats.frames_sent += len(frames)
            stats.bytes_sent += len(data)
            if client.writer.transport.get_write_buffer_size() > MAX_CLIENT_BACKLOG:
                log.warning("gnss client %s too slow; dropping it", stats.peer)
                client.writer.close()
                self._clients.remove(client)


@contextlib.asynccontextmanager
async def running_receiver(
    config: GnssConfig | None = None, clock: SimClock | None = None, host: str = "127.0.0.1"
) -> AsyncIterator[GnssReceiver]:
    """A started receiver on a free port, stopped on exit (for tests and tools)."""
    receiver = GnssReceiver(config, clock)
    await receiver.start(host, 0)
    try:
        yield receiver
    finally:
        await receiver.stop()
