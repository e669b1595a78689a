"""The base station's RTCM3 reader against the real simulated receiver, over TCP and a pty serial."""

from __future__ import annotations

import asyncio
import contextlib
import os
import tty
from dataclasses import replace

import pytest
from pydantic import ValidationError
from pyrtcm import RTCMReader

from assetlink.rtk import (
    Backoff,
    RateMeter,
    RtkConfig,
    RtkReader,
    RtkStats,
    SerialSource,
    TcpSource,
    parse_source,
    rtk_state,
    source_url,
    to_telemetry,
)
from sim.clock import SimClock
from sim.gnss import GnssConfig, GnssReceiver, running_receiver
from tests.polling import eventually

SPEED = 25.0


@contextlib.asynccontextmanager
async def reading(config: RtkConfig, sink: list[bytes]):  # type: ignore[no-untyped-def]
    async def on_frame(frame: bytes) -> None:
        sink.append(frame)

    reader = RtkReader(config, on_frame)
    reader.start()
    try:
        yield reader
    finally:
        await reader.stop()


def assert_consecutive_epochs(frames: list[bytes], rx: GnssReceiver) -> list[int]:
    """`frames` are whole consecutive epochs of the model, byte for byte."""
    per_epoch = len(rx.model.message_types)
    assert len(frames) % per_epoch == 0
    first = (RTCMReader.parse(frames[1]).DF004 - rx.config.start_tow_ms) // 1000
    epochs = list(range(first, first + len(frames) // per_epoch))
    assert frames == [f for e in epochs for f in rx.model.frames(e)]
    return epochs


def test_parse_source() -> None:
    assert parse_source("tcp://127.0.0.1:5021") == TcpSource("127.0.0.1", 5021)
    assert parse_source("serial:///dev/ttyUSB0?baud=57600") == SerialSource("/dev/ttyUSB0", 57600)
    assert parse_source("serial:///dev/ttyACM1") == SerialSource("/dev/ttyACM1", 115200)
    for bad in ("udp://x:1", "tcp://nohost", "serial://", "junk"):
        with pytest.raises(ValueError):
            parse_source(bad)
    with pytest.raises(ValidationError):
        RtkConfig(source="http://example.com/")


def test_source_url_from_host_port_or_device_settings() -> None:
    assert source_url("10.0.0.2", 2101) == "tcp://10.0.0.2:2101"
    url = source_url(serial_device="/dev/ttyACM0", baudrate=38400)
    assert parse_source(url) == SerialSource("/dev/ttyACM0", 38400)
    assert parse_source(source_url()) == TcpSource("127.0.0.1", 5021)


def test_state_and_telemetry_from_stats() -> None:
    base = RtkStats(source="tcp://h:1", connected=True, connects=1, good_frames=40, bad_frames=2,
                    bytes_received=9000, good_bytes=8000, skipped_bytes=900, dropped_frames=0,
                    frames_per_s=4.0, bytes_per_s=515.0, last_frame_age_s=0.4,
                    message_counts={1005: 10})  # fmt: skip
    assert rtk_state(base) == "streaming"
    assert rtk_state(replace(base, last_frame_age_s=9.0)) == "stale"
    assert rtk_state(replace(base, last_frame_age_s=None)) == "waiting"
    assert rtk_state(replace(base, connected=False)) == "disconnected"
    t = to_telemetry(base)
    assert (t.state, t.corrections_rate, t.frames_total, t.bad_frames) == ("streaming", 4.0, 40, 2)


def test_backoff_doubles_to_a_cap_and_resets() -> None:
    b = Backoff(0.5, 4.0)
    assert [b.failure() for _ in range(6)] == [0.5, 1.0, 2.0, 4.0, 4.0, 4.0]
    b.success()
    assert b.failure() == 0.5


def test_rate_meter_slides() -> None:
    m = RateMeter(window_s=10.0)
    for t in range(20):  # one 100-byte frame per second
        m.add(float(t), 100)
    assert m.rates(19.5) == (1.0, 100.0)
    assert m.rates(25.0) == pytest.approx((0.4, 40.0))  # frames at 16..19 remain
    assert m.rates(100.0) == (0.0, 0.0)


async def test_frames_pass_through_intact_and_in_order_over_tcp() -> None:
    got: list[bytes] = []
    async with running_receiver(GnssConfig(seed=2), SimClock(SPEED)) as rx:
        cfg = RtkConfig(source=f"tcp://127.0.0.1:{rx.port}")
        async with reading(cfg, got) as reader:
            iterated: list[bytes] = []

            async def consume() -> None:
                async for frame in reader.frames():
                    iterated.append(frame)

            consumer = asyncio.create_task(consume())
            await eventually(lambda: len(iterated) >= 12)
            await eventually(lambda: len(got) >= 40)
            rx.set_faults(streaming=False)
            await eventually(lambda: reader.stats().bytes_received == rx.clients[0].bytes_sent)
            consumer.cancel()
            stats = reader.stats()
        epochs = assert_consecutive_epochs(got, rx)
        assert len(epochs) >= 10
        start = got.index(iterated[0])  # the iterator joined late, then saw the same sequence
        assert got[start : start + len(iterated)] == iterated
        for frame in got:
            RTCMReader.parse(frame, validate=1)
        assert stats.good_frames == len(got) and stats.bad_frames == 0 and stats.skipped_bytes == 0
        assert stats.good_bytes == stats.bytes_received == sum(map(len, got))
        assert stats.message_counts == {
            1005: len(epochs),
            1077: len(epochs),
            1097: len(epochs),
            1230: len(epochs),
        }
        assert stats.frames_per_s > 0 and stats.bytes_per_s > 0
        assert stats.last_frame_age_s is not None and stats.last_frame_age_s >= 0
        assert stats.connects == 1 and stats.dropped_frames == 0


async def test_garbage_and_corrupted_frames_are_counted_dropped_and_resynced() -> None:
    got: list[bytes] = []
    async with running_receiver(GnssConfig(seed=9), SimClock(SPEED)) as rx:
        async with reading(RtkConfig(source=f"tcp://127.0.0.1:{rx.port}"), got) as reader:
            await eventually(lambda: len(rx.clients) == 1)
            rx.set_faults(garbage_bytes=200, corrupt_fraction=0.25)
            client = rx.clients[0]
            await eventually(lambda: client.frames_corrupted >= 12 and client.garbage_bytes >= 2000)
            rx.set_faults(garbage_bytes=0, corrupt_fraction=0.0)
            clean_from = client.epochs
            await eventually(lambda: client.epochs >= clean_from + 4)
            rx.set_faults(streaming=False)
            await eventually(lambda: reader.stats().bytes_received == client.bytes_sent)
            await eventually(lambda: reader.stats().good_frames == len(got))
            stats = reader.stats()
        assert stats.good_frames == client.frames_sent - client.frames_corrupted
        assert stats.bad_frames >= client.frames_corrupted
        assert stats.skipped_bytes >= client.garbage_bytes
        assert stats.good_bytes + stats.skipped_bytes <= stats.bytes_received
        remaining = iter([f for e in range(rx.last_epoch + 1) for f in rx.model.frames(e)])
        assert all(any(f == g for g in remaining) for f in got)  # intact and in order
        for frame in got:
            RTCMReader.parse(frame, validate=1)
        # the stream resynchronised: the clean tail arrived whole
        tail = got[-4 * len(rx.model.message_types) :]
        assert_consecutive_epochs(tail, rx)


async def test_reconnects_after_a_receiver_restart() -> None:
    got: list[bytes] = []
    rx = GnssReceiver(GnssConfig(), SimClock(SPEED))
    await rx.start("127.0.0.1", 0)
    port = rx.port
    cfg = RtkConfig(source=f"tcp://127.0.0.1:{port}", reconnect_min_s=0.05, reconnect_max_s=0.2)
    try:
        async with reading(cfg, got) as reader:
            await eventually(lambda: len(got) >= 8)
            await rx.stop()
            await eventually(lambda: not reader.stats().connected)
            before = len(got)
            rx = GnssReceiver(GnssConfig(), SimClock(SPEED))
            await rx.start("127.0.0.1", port)
            await eventually(lambda: reader.stats().connects == 2)
            await eventually(lambda: len(got) >= before + 8)
            stats = reader.stats()
        assert stats.bad_frames == 0
        for frame in got:
            RTCMReader.parse(frame, validate=1)
    finally:
        await rx.stop()


async def test_a_silent_source_is_reconnected() -> None:
    got: list[bytes] = []
    async with running_receiver(GnssConfig(), SimClock(SPEED)) as rx:
        cfg = RtkConfig(
            source=f"tcp://127.0.0.1:{rx.port}",
            idle_reconnect_s=0.3,
            reconnect_min_s=0.02,
            reconnect_max_s=0.05,
        )
        async with reading(cfg, got) as reader:
            await eventually(lambda: len(got) >= 4)
            rx.set_faults(streaming=False)  # the connection stays up, but nothing comes
            await eventually(lambda: reader.stats().connects >= 2)
            rx.set_faults(streaming=True)
            before = len(got)
            await eventually(lambda: len(got) >= before + 8)
        assert reader.stats().bad_frames == 0


async def test_unreachable_source_is_retried_without_crashing() -> None:
    async with running_receiver(GnssConfig(), SimClock(SPEED)) as rx:
        port = rx.port
    got: list[bytes] = []
    cfg = RtkConfig(source=f"tcp://127.0.0.1:{port}", reconnect_min_s=0.02, reconnect_max_s=0.05)
    async with reading(cfg, got) as reader:
        rx = GnssReceiver(GnssConfig(), SimClock(SPEED))
        await rx.start("127.0.0.1", port)
        try:
            await eventually(lambda: len(got) >= 4)
            assert reader.stats().connects == 1
        finally:
            await rx.stop()


async def test_serial_source_through_a_pty() -> None:
    master, slave = os.openpty()
    tty.setraw(slave)
    got: list[bytes] = []
    try:
        async with running_receiver(GnssConfig(seed=4), SimClock(SPEED)) as rx:
            cfg = RtkConfig(source=f"serial://{os.ttyname(slave)}?baud=115200")
            async with reading(cfg, got) as reader:
                await eventually(lambda: reader.stats().connected)
                tcp_reader, tcp_writer = await asyncio.open_connection("127.0.0.1", rx.port)

                async def bridge() -> (
                    None
                ):  # the receiver's serial output, as a wire would carry it
                    while data := await tcp_reader.read(4096):
                        while data:
                            n = await asyncio.to_thread(os.write, master, data)
                            data = data[n:]

                task = asyncio.create_task(bridge())
                try:
                    await eventually(lambda: len(got) >= 24)
                    rx.set_faults(streaming=False)
                    await eventually(
                        lambda: reader.stats().bytes_received == rx.clients[0].bytes_sent
                    )
                finally:
                    task.cancel()
                    tcp_writer.close()
                stats = reader.stats()
                assert stats.bad_frames == 0 and stats.good_frames == len(got)
                assert_consecutive_epochs(got, rx)
                os.close(master)  # unplug the device
                master = -1
                await eventually(lambda: not reader.stats().connected)
    finally:
        if master >= 0:
            os.close(master)
        os.close(slave)
