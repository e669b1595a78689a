"""The caster's own TCP port, for NTRIP 1 and 2 clients: RTKLIB's str2str (Debian's rtklib) and
pygnssutils pull the live corrections the simulated receiver's frames become, and raw requests
show each answer of both protocol versions."""

from __future__ import annotations

import asyncio
import base64
import contextlib
import json
import queue
from collections.abc import AsyncIterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest
from pygnssutils import GNSSNTRIPClient

from assetlink.rtk import RtkConfig, RtkReader
from protocol.rtcm import Reframer, frame_ok, message_type
from server.stations import caster as caster_module
from server.stations.caster import Caster, parse_request
from server.stations.ntrip import LiveCorrections, Mountpoint, sourcetable
from sim.clock import SimClock
from sim.gnss import GnssConfig, GnssReceiver, running_receiver
from tests.polling import eventually
from tests.rtk import frames_in, stop, str2str
from tests.server.test_ntrip import SPEED, Source, authenticate, mountpoints


@dataclass
class Running:
    caster: Caster
    source: Source
    receiver: GnssReceiver


@pytest.fixture
async def ntrip() -> AsyncIterator[Running]:
    """receiver (sim) -> RtkReader (base station) -> live fan-out -> the caster on a free port."""
    async with running_receiver(GnssConfig(seed=22), SimClock(SPEED)) as rx:
        hub = LiveCorrections()
        source = Source(mountpoints(rx), hub=hub)

        async def publish(frame: bytes) -> None:
            hub.publish("BASE1", frame)

        reader = RtkReader(RtkConfig(source=f"tcp://127.0.0.1:{rx.port}"), publish)
        reader.start()
        caster = await Caster(source, authenticate).start("127.0.0.1", 0)
        try:
            yield Running(caster, source, rx)
        finally:
            await caster.close()
            await reader.stop()


GGA = b"$GPGGA,120000.00,4110.6800,N,00835.8800,W,4,12,0.6,100.0,M,50.0,M,1.0,0000*4B\r\n"


def basic(user: str, password: str) -> str:
    return "Basic " + base64.b64encode(f"{user}:{password}".encode()).decode()


async def ask(port: int, request: str, then: bytes = b"", until_close: bool = True) -> bytes:
    """Send one request; everything the caster answers until it closes (or the first read)."""
    reader, writer = await asyncio.open_connection("127.0.0.1", port)
    try:
        writer.write(request.encode() + then)
        await writer.drain()
        async with asyncio.timeout(10):
            return await (reader.read() if until_close else reader.read(65536))
    finally:
        writer.close()


def v1(path: str, auth: str | None = basic("alice", "s3cret"), extra: str = "") -> str:
    """An NTRIP 1 request as RTKLIB's str2str sends it."""
    lines = [f"GET {path} HTTP/1.0", "User-Agent: NTRIP RTKLIB/2.4.3"]
    if auth:
        lines.append(f"Authorization: {auth}")
    return "\r\n".join(lines) + "\r\n" + extra + "\r\n"


def v2(path: str, auth: str | None = basic("alice", "s3cret")) -> str:
    return v1(path, auth, "Host: caster\r\nNtrip-Version: Ntrip/2.0\r\n").replace(
        "HTTP/1.0", "HTTP/1.1"
    )


async def test_rtklib_str2str_pulls_the_live_corrections_as_an_ntrip_1_client(
    ntrip: Running, tmp_path: Path
):
    out = tmp_path / "corrections.rtcm3"
    rover = await str2str(f"ntrip://alice:s3cret@127.0.0.1:{ntrip.caster.port}/BASE1", out)
    try:
        await eventually(lambda: len(frames_in(out)) >= 24, within=30, what="frames str2str wrote")
    finally:
        await stop(rover)
    data = out.read_bytes()
    reframer = Reframer()
    frames = list(reframer.feed(data))
    assert data[0] == 0xD3, data[:40]  # the ICY line stays out of the data: nothing but RTCM3
    assert reframer.skipped_bytes == 0 and reframer.bad_frames == 0
    assert {message_type(f) for f in frames} == {1005, 1077, 1097, 1230}
    model = [
        f for e in range(ntrip.receiver.last_epoch + 1) for f in ntrip.receiver.model.frames(e)
    ]
    assert all(f in model for f in frames)  # intact
    await eventually(lambda: ntrip.source.open_subscriptions == 0, what="subscription released")


@pytest.mark.parametrize("version", ["1.0", "2.0"])
async def test_pygnssutils_pulls_corrections_in_either_version(ntrip: Running, version: str):
    out: queue.Queue[Any] = queue.Queue()
    client = GNSSNTRIPClient(retries=0, timeout=5, verbosity=0)
    client.run(server="127.0.0.1", port=ntrip.caster.port, mountpoint="BASE1",
               ntripuser="alice", ntrippassword="s3cret", version=version, output=out)  # fmt: skip
    try:
        await eventually(lambda: out.qsize() >= 12, what=f"frames over NTRIP {version}")
    finally:
        client.stop()
    frames = [out.get_nowait()[0] for _ in range(out.qsize())]
    assert all(frame_ok(f) for f in frames)
    assert {message_type(f) for f in frames} >= {1005, 1077}


async def test_the_sourcetable_in_either_version_lists_what_the_caller_may_see(ntrip: Running):
    table = sourcetable([m for m in ntrip.source.items if m.name in ("BASE1", "PUBLIC")]).encode()
    one = await ask(ntrip.caster.port, v1("/"))
    head, _, body = one.partition(b"\r\n\r\n")
    assert head.startswith(b"SOURCETABLE 200 OK\r\n") and body == table
    assert f"Content-Length: {len(table)}".encode() in head
    two = await ask(ntrip.caster.port, v2("/ntrip/"))
    head, _, body = two.partition(b"\r\n\r\n")
    assert head.startswith(b"HTTP/1.1 200 OK\r\n") and body == table
    assert b"Content-Type: gnss/sourcetable" in head and b"Ntrip-Version: Ntrip/2.0" in head
    anonymous = await ask(ntrip.caster.port, v1("/", auth=None))
    assert anonymous.endswith(sourcetable([Mountpoint("PUBLIC", "Open demo")]).encode())


async def test_a_mountpoint_the_caller_does_not_see_gets_the_sourcetable_or_404(ntrip: Running):
    for name in ("NOPE", "BASE2"):  # unknown; another organisation's base
        one = await ask(ntrip.caster.port, v1(f"/{name}"))
        assert one.startswith(b"SOURCETABLE 200 OK\r\n") and b"STR;BASE2" not in one
        two = await ask(ntrip.caster.port, v2(f"/{name}"))
        assert two.startswith(b"HTTP/1.1 404 Not Found\r\n")
        assert json.loads(two.partition(b"\r\n\r\n")[2])["error"]["code"] == "not_found"
    assert ntrip.source.open_subscriptions == 0


async def test_bad_or_missing_credentials_get_401_with_a_basic_challenge(ntrip: Running):
    for auth in (None, basic("alice", "wrong"), "Basic %%%"):
        one = await ask(ntrip.caster.port, v1("/BASE1", auth=auth))
        assert one.startswith(b"HTTP/1.0 401 Unauthorized\r\n"), one[:60]
        assert b'WWW-Authenticate: Basic realm="Aerobase NTRIP caster"' in one
        two = await ask(ntrip.caster.port, v2("/BASE1", auth=auth))
        assert two.startswith(b"HTTP/1.1 401 Unauthorized\r\n")
    assert (await ask(ntrip.caster.port, v1("/", basic("bob", "x")))).startswith(b"HTTP/1.0 401")
    # a rover that sends its GGA at once still reads its answer (on loopback this passes without
    # the caster's half-close too; the 503 test is the one that needs it)
    refused = await ask(ntrip.caster.port, v1("/BASE1", basic("alice", "wrong")), then=GGA * 400)
    assert refused.startswith(b"HTTP/1.0 401 Unauthorized\r\n")
    assert ntrip.source.open_subscriptions == 0


async def test_what_is_not_an_ntrip_client_request_is_refused_not_served(ntrip: Running):
    port = ntrip.caster.port
    assert (await ask(port, "hello\r\n\r\n")).startswith(b"HTTP/1.0 400 Bad Request\r\n")
    assert (await ask(port, "GET /" + "x" * 9000)).startswith(b"HTTP/1.0 400")  # no end: cut off
    source = "SOURCE s3cret /BASE1\r\nSource-Agent: NTRIP test\r\n\r\n"  # an NTRIP 1 server
    assert (await ask(port, source)).startswith(b"HTTP/1.0 405 Method Not Allowed\r\n")
    post = v2("/BASE1").replace("GET", "POST", 1)
    assert (await ask(port, post)).startswith(b"HTTP/1.1 405")
    assert ntrip.source.open_subscriptions == 0


async def test_an_ntrip_1_stream_is_icy_then_raw_frames_and_gga_from_the_rover_is_taken(
    ntrip: Running,
):
    reader, writer = await asyncio.open_connection("127.0.0.1", ntrip.caster.port)
    try:
        writer.write(v1("/BASE1").encode() + GGA)  # rovers send their position as data
        async with asyncio.timeout(10):
            assert await reader.readexactly(12) == b"ICY 200 OK\r\n"
        reframer, frames = Reframer(), []
        async with asyncio.timeout(20):
            while len(frames) < 12:
                frames += reframer.feed(await reader.read(4096))
                writer.write(GGA)  # every so often, as a rover does
        assert reframer.skipped_bytes == 0 and reframer.bad_frames == 0
    finally:
        writer.close()
    await eventually(lambda: ntrip.source.open_subscriptions == 0, what="its leaving noticed")


async def test_an_ntrip_2_stream_is_chunked_gnss_data(ntrip: Running):
    reader, writer = await asyncio.open_connection("127.0.0.1", ntrip.caster.port)
    try:
        writer.write(v2("/ntrip/BASE1").encode())
        async with asyncio.timeout(10):
            head = await reader.readuntil(b"\r\n\r\n")
        assert head.startswith(b"HTTP/1.1 200 OK\r\n")
        for field in (b"Content-Type: gnss/data", b"Transfer-Encoding: chunked",
                      b"Ntrip-Version: Ntrip/2.0"):  # fmt: skip
            assert field in head
        frames = []
        async with asyncio.timeout(20):
            while len(frames) < 8:  # each chunk one whole frame
                size = int((await reader.readuntil(b"\r\n"))[:-2], 16)
                frames.append(await reader.readexactly(size))
                assert await reader.readexactly(2) == b"\r\n"
        assert all(frame_ok(f) for f in frames)
    finally:
        writer.close()


async def test_closing_the_caster_ends_its_streams(ntrip: Running):
    reader, writer = await asyncio.open_connection("127.0.0.1", ntrip.caster.port)
    writer.write(v1("/BASE1").encode())
    async with asyncio.timeout(10):
        assert await reader.readexactly(12) == b"ICY 200 OK\r\n"
    await eventually(lambda: ntrip.caster.connected == 1)
    await ntrip.caster.close()
    async with asyncio.timeout(10):
        while await reader.read(65536):
            pass  # frames sent before the close, then the end
    assert ntrip.caster.connected == 0 and ntrip.source.open_subscriptions == 0
    with contextlib.suppress(ConnectionError):
        writer.close()


async def test_closing_the_caster_cuts_off_a_rover_that_stopped_reading():
    class Flood:  # a base sending more than any link takes
        def mountpoints(self) -> list[Mountpoint]:
            return [Mountpoint("BASE1", organisation_id="org-a")]

        async def subscribe(self, mountpoint: Mountpoint) -> AsyncIterator[bytes]:
            while True:
                yield b"\xd3" + bytes(65535)
                await asyncio.sleep(0)

    flooded = await Caster(Flood(), authenticate).start("127.0.0.1", 0)
    reader, writer = await asyncio.open_connection("127.0.0.1", flooded.port)
    writer.write(v1("/BASE1").encode())
    async with asyncio.timeout(10):
        assert await reader.readexactly(12) == b"ICY 200 OK\r\n"
    # the rover reads no more: the caster's writes back up behind it
    stalled = next(iter(flooded._clients.values())).transport
    await eventually(lambda: stalled.get_write_buffer_size() > 0, what="the caster blocked")
    async with asyncio.timeout(3 * caster_module.CLOSE_WAIT_S + 2):
        await flooded.close()  # not held for SEND_TIMEOUT_S by the stalled rover
    assert flooded.connected == 0
    writer.close()


async def test_a_client_over_the_limit_is_answered_503_and_the_others_keep_streaming(
    ntrip: Running,
):
    full = await Caster(ntrip.source, authenticate, max_clients=1).start("127.0.0.1", 0)
    try:
        reader, writer = await asyncio.open_connection("127.0.0.1", full.port)
        writer.write(v1("/BASE1").encode())
        async with asyncio.timeout(10):
            assert await reader.readexactly(12) == b"ICY 200 OK\r\n"
        assert (await ask(full.port, v1("/BASE1"))).startswith(b"HTTP/1.0 503 Service Unavailable")
        async with asyncio.timeout(10):
            assert (await reader.read(4096))[0] == 0xD3  # the first client still gets frames
        writer.close()
    finally:
        await full.close()


async def test_when_the_database_is_away_a_client_is_told_503_not_hung_up_on():
    async def database_away(username: str, password: str, address: str | None) -> str | None:
        raise OSError("connection refused")  # what asyncpg raises with PostgreSQL down

    broken = await Caster(Source([]), database_away).start("127.0.0.1", 0)
    try:
        for request in (v1("/BASE1"), v2("/BASE1")):
            answer = await ask(broken.port, request)
            assert b" 503 Service Unavailable\r\n" in answer.split(b"\r\n", 1)[0] + b"\r\n"
            assert b"try again" in answer
    finally:
        await broken.close()


async def test_a_client_that_says_nothing_is_let_go(ntrip: Running, monkeypatch):
    monkeypatch.setattr(caster_module, "HEAD_TIMEOUT_S", 0.2)
    reader, writer = await asyncio.open_connection("127.0.0.1", ntrip.caster.port)
    async with asyncio.timeout(10):
        assert (await reader.read()).startswith(b"HTTP/1.0 400 Bad Request\r\n")
    writer.close()
    await eventually(lambda: ntrip.caster.connected == 0)


async def test_behind_a_proxy_the_client_is_the_one_its_proxy_protocol_line_names(
    ntrip: Running,
):
    addresses: list[str | None] = []

    async def recording(username: str, password: str, address: str | None) -> str | None:
        addresses.append(address)
        return await authenticate(username, password, address)

    proxied = await Caster(ntrip.source, recording, proxy_protocol=True).start("127.0.0.1", 0)
    try:
        line = "PROXY TCP4 203.0.113.9 127.0.0.1 40001 2101\r\n"
        answer = await ask(proxied.port, line + v1("/"))
        assert answer.startswith(b"SOURCETABLE 200 OK\r\n") and addresses == ["203.0.113.9"]
        line6 = "PROXY TCP6 2001:db8::7 ::1 40001 2101\r\n"
        assert (await ask(proxied.port, line6 + v1("/"))).startswith(b"SOURCETABLE 200")
        assert addresses[-1] == "2001:db8::7"
        # the proxy's own health check: no client, the connection's peer stands
        assert (await ask(proxied.port, "PROXY UNKNOWN\r\n" + v1("/"))).startswith(b"SOURCE")
        assert addresses[-1] == "127.0.0.1"
        # straight to the caster, or a forged line: refused
        for request in (v1("/"), "PROXY TCP4 me 127.0.0.1 1 2\r\n" + v1("/")):
            assert (await ask(proxied.port, request)).startswith(b"HTTP/1.0 400 Bad Request")
        assert len(addresses) == 3
    finally:
        await proxied.close()


def test_requests_parse_with_either_line_end_and_the_ntrip_prefix():
    r = parse_request(b"GET /ntrip/BASE1?x=1 HTTP/1.1\nntrip-version: Ntrip/2.0\n\n")
    assert (r.method, r.mountpoint, r.version_2) == ("GET", "BASE1", True)
    r = parse_request(b"get /BASE1 HTTP/1.0\r\nUser-Agent: x\r\n\r\n")
    assert (r.method, r.mountpoint, r.version_2) == ("GET", "BASE1", False)
    assert parse_request(b"GET / HTTP/1.0\r\n\r\n").mountpoint == ""
    assert parse_request(b"GET /ntrip HTTP/1.0\r\n\r\n").mountpoint == ""
