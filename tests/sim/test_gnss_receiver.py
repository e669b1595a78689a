"""The simulated base receiver over real TCP: epochs to many clients, fault switches, control API."""

from __future__ import annotations

import asyncio
import contextlib
import itertools
import socket
from collections.abc import AsyncIterator

import httpx
import uvicorn
from fastapi import FastAPI
from pyrtcm import RTCMReader

from protocol.rtcm import Reframer, message_type
from sim.clock import SimClock
from sim.gnss import GnssConfig, GnssReceiver, gnss_router, running_receiver
from tests.polling import eventually

SPEED = 25.0  # 25 epochs per wall second


class FrameSink:
    """A TCP client of the receiver that reframes what it reads."""

    def __init__(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        self.reader, self.writer = reader, writer
        self.reframer = Reframer()
        self.frames: list[bytes] = []
        self.bytes = 0
        self.eof = False
        self._task = asyncio.create_task(self._pump())

    async def _pump(self) -> None:
        with contextlib.suppress(ConnectionError):
            while data := await self.reader.read(65536):
                self.bytes += len(data)
                self.frames.extend(self.reframer.feed(data))
        self.eof = True

    async def close(self) -> None:
        self.writer.close()
        self._task.cancel()
        with contextlib.suppress(asyncio.CancelledError, ConnectionError):
            await self._task


@contextlib.asynccontextmanager
async def sink(port: int) -> AsyncIterator[FrameSink]:
    reader, writer = await asyncio.open_connection("127.0.0.1", port)
    s = FrameSink(reader, writer)
    try:
        yield s
    finally:
        await s.close()


def epochs_of(frames: list[bytes], receiver: GnssReceiver) -> list[int]:
    """Epoch indices of a run of complete clean epochs, checked frame by frame against the model."""
    per_epoch = len(receiver.model.message_types)
    assert len(frames) % per_epoch == 0
    first_tow = RTCMReader.parse(frames[1]).DF004
    first = (first_tow - receiver.config.start_tow_ms) // 1000
    epochs = list(range(first, first + len(frames) // per_epoch))
    expected = [f for e in epochs for f in receiver.model.frames(e)]
    assert frames == expected
    return epochs


async def test_two_clients_receive_identical_consecutive_epochs() -> None:
    async with running_receiver(GnssConfig(seed=11), SimClock(SPEED)) as rx:
        async with sink(rx.port) as a, sink(rx.port) as b:
            await eventually(lambda: len(rx.clients) == 2)
            await eventually(lambda: len(a.frames) >= 20 and len(b.frames) >= 20)
            # both joined before the same epoch boundary? compare the overlap
            ea, eb = epochs_of(a.frames[:20], rx), epochs_of(b.frames[:20], rx)
            assert ea == list(range(ea[0], ea[0] + 5)) and eb == list(range(eb[0], eb[0] + 5))
            for frame in a.frames[:20]:
                RTCMReader.parse(frame, validate=1)
            assert a.reframer.bad_frames == 0 and a.reframer.skipped_bytes == 0
            stats = next(c for c in rx.clients)
            assert stats.frames_sent >= 20 and stats.frames_corrupted == 0


async def test_stop_streaming_then_resume() -> None:
    clock = SimClock(SPEED)
    async with running_receiver(GnssConfig(), clock) as rx, sink(rx.port) as s:
        await eventually(lambda: len(s.frames) >= 8)
        rx.set_faults(streaming=False)
        sent = rx.epochs_sent
        stopped_at = clock.now()
        await eventually(lambda: clock.now() > stopped_at + 4)
        assert rx.epochs_sent <= sent + 1  # an epoch already being sent may complete
        quiet = rx.epochs_sent
        bytes_then = rx.clients[0].bytes_sent
        await eventually(lambda: s.bytes == bytes_then)
        await eventually(lambda: clock.now() > stopped_at + 8)
        assert rx.epochs_sent == quiet and rx.clients[0].bytes_sent == bytes_then
        rx.set_faults(streaming=True)
        await eventually(lambda: rx.epochs_sent >= quiet + 3)
        await eventually(lambda: s.bytes == rx.clients[0].bytes_sent)
        assert s.reframer.bad_frames == 0
        per_epoch = len(rx.model.message_types)
        groups = [s.frames[i : i + per_epoch] for i in range(0, len(s.frames), per_epoch)]
        tows = [RTCMReader.parse(g[1]).DF004 for g in groups]
        epochs = [(t - rx.config.start_tow_ms) // 1000 for t in tows]
        for group, epoch in zip(groups, epochs, strict=True):
            assert group == rx.model.frames(epoch)
        gaps = [b - a for a, b in itertools.pairwise(epochs)]
        assert all(g >= 1 for g in gaps) and max(gaps) >= 4  # the pause, and nothing replayed


async def test_garbage_and_corruption_are_injected_and_accounted_for() -> None:
    async with running_receiver(GnssConfig(seed=5), SimClock(SPEED)) as rx, sink(rx.port) as s:
        await eventually(lambda: len(rx.clients) == 1)
        rx.set_faults(garbage_bytes=300, corrupt_fraction=0.3)
        client = rx.clients[0]
        await eventually(lambda: client.frames_corrupted >= 10 and client.garbage_bytes >= 3000)
        rx.set_faults(garbage_bytes=0, corrupt_fraction=0.0)
        marker = client.epochs
        await eventually(
            lambda: client.epochs >= marker + 4
        )  # clean tail resolves any false header
        rx.set_faults(streaming=False)
        await eventually(lambda: s.bytes == client.bytes_sent)
        good = s.frames
        assert len(good) == client.frames_sent - client.frames_corrupted
        assert s.reframer.bad_frames >= client.frames_corrupted
        assert s.reframer.skipped_bytes >= client.garbage_bytes
        # every surviving frame is one the model produced, in order, and parses with a good CRC
        all_frames = [f for e in range(rx.last_epoch + 1) for f in rx.model.frames(e)]
        remaining = iter(all_frames)
        assert all(any(f == g for g in remaining) for f in good)  # an ordered subsequence
        for frame in good:
            RTCMReader.parse(frame, validate=1)
        assert {message_type(f) for f in good} == {1005, 1077, 1097, 1230}


async def test_disconnect_and_restart_on_a_fixed_port() -> None:
    rx = GnssReceiver(GnssConfig(), SimClock(SPEED))
    await rx.start("127.0.0.1", 0)
    port = rx.port
    try:
        async with sink(port) as s:
            await eventually(lambda: len(s.frames) >= 4)
            assert await rx.disconnect_clients() == 1
            await eventually(lambda: s.eof)
        await rx.stop()
        rx = GnssReceiver(GnssConfig(), SimClock(SPEED))
        await rx.start("127.0.0.1", port)
        async with sink(port) as s:
            await eventually(lambda: len(s.frames) >= 4)
    finally:
        await rx.stop()


@contextlib.asynccontextmanager
async def serve(app: FastAPI) -> AsyncIterator[str]:
    """Serve `app` with uvicorn on a free port; yields its base URL."""
    sock = socket.socket()
    sock.bind(("127.0.0.1", 0))
    port = sock.getsockname()[1]
    server = uvicorn.Server(uvicorn.Config(app, log_level="warning", lifespan="off"))
    task = asyncio.create_task(server.serve(sockets=[sock]))
    try:
        await eventually(lambda: server.started)
        yield f"http://127.0.0.1:{port}"
    finally:
        server.should_exit = True
        await task
        sock.close()


async def test_control_router_switches_faults_and_reports_status() -> None:
    async with running_receiver(GnssConfig(station_id=77), SimClock(SPEED)) as rx:
        app = FastAPI()
        app.include_router(gnss_router(rx))
        async with serve(app) as url, httpx.AsyncClient(base_url=url) as http, sink(rx.port):
            await eventually(lambda: rx.epochs_sent >= 2)
            status = (await http.get("/gnss")).json()
            assert status["config"]["station_id"] == 77
            assert status["message_types"] == [1005, 1077, 1097, 1230]
            assert len(status["clients"]) == 1
            r = await http.post("/gnss/faults", json={"garbage_bytes": 10, "corrupt_fraction": 0.5})
            assert r.status_code == 200
            assert r.json() == {"streaming": True, "garbage_bytes": 10, "corrupt_fraction": 0.5}
            assert rx.faults.garbage_bytes == 10
            r = await http.post("/gnss/faults", json={"streaming": False})
            assert r.json()["garbage_bytes"] == 10 and r.json()["streaming"] is False
            assert (
                await http.post("/gnss/faults", json={"corrupt_fraction": 2})
            ).status_code == 422
            assert (await http.post("/gnss/faults", json={"bogus": 1})).status_code == 422
            r = await http.post("/gnss/faults/clear")
            assert r.json() == {"streaming": True, "garbage_bytes": 0, "corrupt_fraction": 0.0}
            r = await http.post("/gnss/disconnect")
            assert r.json() == {"disconnected": 1}
            await eventually(lambda: not rx.clients)
