"""The simulated camera end to end: rendered frames over the real TCP transport, with timestamps."""

from __future__ import annotations

import asyncio
import itertools
import math

import numpy as np

from asset_agent.precland.detect import PadDetector
from asset_agent.precland.transport import (
    FRAME_HEADER,
    TransportError,
    parse_frame_header,
    stream_frames,
)
from sim.camera.render import PadRenderer
from sim.camera.server import HEADER, CameraServer, encode_frame
from sim.clock import SimClock
from tests.polling import eventually


def scripted_pose(clock: SimClock):
    """A slow spiral descent, as a function of the world clock."""

    def pose_at(t: float):
        return (0.2 * math.cos(0.2 * t), 0.2 * math.sin(0.2 * t), 3.0 - 0.05 * t, 0.0, 0.0, 0.1 * t)

    return pose_at, (lambda: pose_at(clock.now()))


def test_sim_and_agent_agree_on_the_header():
    assert HEADER.format == FRAME_HEADER.format and HEADER.size == 28
    img = np.zeros((4, 5, 3), np.uint8)
    data = encode_frame(7, 12.5, img)
    assert parse_frame_header(data[:28]) == (7, 12.5, 5, 4, 0, 60)
    try:
        parse_frame_header(b"XXXX" + data[4:28])
    except TransportError:
        pass
    else:
        raise AssertionError("bad magic accepted")


async def test_frames_arrive_with_capture_timestamps_and_match_the_pose_at_that_time():
    clock = SimClock(speed=2.0)
    pose_at, pose_fn = scripted_pose(clock)
    server = CameraServer(pose_fn, clock, PadRenderer(), fps=30.0)
    port = await server.start()
    detector = PadDetector()
    frames = []
    try:
        async for frame in stream_frames("127.0.0.1", port):
            frames.append(frame)
            if len(frames) == 12:
                break
    finally:
        await server.stop()
    seqs = [f.seq for f in frames]
    stamps = [f.capture_ts for f in frames]
    assert seqs == sorted(seqs) and len(set(seqs)) == len(seqs)
    assert all(b > a for a, b in itertools.pairwise(stamps))
    assert stamps[-1] <= clock.now()
    for f in frames[::4]:
        assert f.image.shape == (480, 640, 3)
        n, e, up, _, _, yaw = pose_at(f.capture_ts)
        p = detector.detect(f.image).pattern
        assert p is not None
        assert abs(p.z - up) < 0.02  # the frame shows the pose at its own timestamp
        c, s = math.cos(yaw), math.sin(yaw)
        assert math.hypot(p.x - (c * -n + s * -e), p.y - (-s * -n + c * -e)) < 0.02


async def test_jpeg_encoding_and_a_late_subscriber():
    clock = SimClock(speed=1.0)
    _, pose_fn = scripted_pose(clock)
    server = CameraServer(pose_fn, clock, fps=30.0, jpeg_quality=90)
    port = await server.start()
    try:
        got = []
        async for frame in stream_frames("127.0.0.1", port):
            got.append(frame)
            if len(got) == 3:
                break
        assert got[0].image.shape == (480, 640, 3)
        # a second subscriber after the first left still gets frames
        async for frame in stream_frames("127.0.0.1", port):
            assert frame.seq > got[-1].seq
            break
        await eventually(lambda: server.frames_sent >= 4)
    finally:
        await server.stop()


async def test_the_client_survives_a_malformed_stream_and_reconnects():
    from asset_agent.precland.transport import frames_forever

    served = []

    async def bad_then_good(reader, writer):
        if not served:
            writer.write(b"NOPE" + bytes(24))  # a malformed header
        else:
            writer.write(encode_frame(5, 1.25, np.zeros((2, 3, 3), np.uint8)))
        served.append(1)
        await writer.drain()
        writer.close()

    server = await asyncio.start_server(bad_then_good, "127.0.0.1", 0)
    port = server.sockets[0].getsockname()[1]
    try:
        stream = frames_forever("127.0.0.1", port, retry_s=0.01)
        frame = await asyncio.wait_for(anext(stream), 10.0)
        await stream.aclose()
    finally:
        server.close()
        await server.wait_closed()
    assert (frame.seq, frame.capture_ts, frame.image.shape) == (5, 1.25, (2, 3, 3))
    assert len(served) >= 2


async def test_stopping_with_a_subscriber_waiting_leaves_no_connection_task_behind():
    """A subscriber connected and waiting for its next frame when the camera stops: its
    connection task ends with the server (left pending it was destroyed with the event loop,
    "Task was destroyed but it is pending", in whatever test ran next)."""
    clock = SimClock(speed=1.0)
    _, pose_fn = scripted_pose(clock)
    server = CameraServer(pose_fn, clock, PadRenderer(), fps=1.0)  # no frame for a second
    port = await server.start()
    _reader, writer = await asyncio.open_connection("127.0.0.1", port)
    try:
        await eventually(lambda: server._slots, 5, "the subscriber's connection")
        (slot,) = server._slots
        await server.stop()
        assert slot.task.done() and not server._slots
    finally:
        writer.close()
