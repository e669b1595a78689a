"""The NTRIP v2 caster router, fed from the simulated receiver through the base station's reader,
pulled by a third-party NTRIP client (pygnssutils) and by raw HTTP."""

from __future__ import annotations

import asyncio
import base64
import contextlib
import queue
import socket
from collections.abc import AsyncIterator
from dataclasses import dataclass
from typing import Any

import httpx
import pytest
import uvicorn
from fastapi import FastAPI
from fastapi.middleware.gzip import GZipMiddleware
from pygnssutils import GNSSNTRIPClient
from pyrtcm import RTCMReader

from assetlink.rtk import RtkConfig, RtkReader
from protocol.rtcm import Reframer, frame_ok, message_type
from server.kit.metrics import REGISTRY
from server.realtime.broker import InProcessBroker
from server.realtime.channels import rtcm_channel
from server.stations.ntrip import (
    LiveCorrections,
    Mountpoint,
    broker_frames,
    format_details,
    mountpoint_name,
    ntrip_router,
    parse_basic_auth,
    sourcetable,
    visible_to,
)
from server.stations.recheck import rechecked
from sim.clock import SimClock
from sim.gnss import BaseStationModel, GnssConfig, GnssReceiver, running_receiver
from tests.polling import eventually

SPEED = 20.0
USERS = {"alice": ("s3cret", "org-a"), "bob": ("hunter2", "org-b")}


async def authenticate(username: str, password: str, address: str | None = None) -> str | None:
    """Organisation users' credentials, as the lead's auth service answers them."""
    known = USERS.get(username)
    return known[1] if known and known[0] == password else None


@dataclass
class Source:
    """Two organisations' bases; live frames from the realtime broker (as the server routes a
    base's `rtcm` messages) or from the in-process fan-out; counts open subscriptions."""

    items: list[Mountpoint]
    broker: InProcessBroker | None = None
    hub: LiveCorrections | None = None
    open_subscriptions: int = 0

    async def mountpoints(self) -> list[Mountpoint]:
        return self.items

    async def subscribe(self, mountpoint: Mountpoint) -> AsyncIterator[bytes]:
        if self.broker is not None:
            frames = broker_frames(self.broker, rtcm_channel(mountpoint.asset_id))
        else:
            assert self.hub is not None
            frames = self.hub.subscribe(mountpoint.name)
        self.open_subscriptions += 1
        try:
            async for frame in frames:
                yield frame
        finally:
            self.open_subscriptions -= 1
            await frames.aclose()


@dataclass
class Caster:
    url: str
    port: int
    source: Source
    receiver: GnssReceiver
    reader: RtkReader


@contextlib.asynccontextmanager
async def serve(app: FastAPI) -> AsyncIterator[int]:
    """Serve `app` with uvicorn on a free port; yields the port."""
    sock = socket.socket()
    sock.bind(("127.0.0.1", 0))
    port = sock.getsockname()[1]
    config = uvicorn.Config(app, log_level="warning", lifespan="off", timeout_graceful_shutdown=2)
    server = uvicorn.Server(config)
    task = asyncio.create_task(server.serve(sockets=[sock]))
    try:
        await eventually(lambda: server.started)
        yield port
    finally:
        server.should_exit = True
        await task
        sock.close()


def mountpoints(rx: GnssReceiver) -> list[Mountpoint]:
    """Organisation A's base (fed by `rx`), organisation B's, and a public one."""
    types = dict.fromkeys(rx.model.message_types, 1.0)
    return [
        Mountpoint("BASE1", "Porto base", format_details=format_details(types), country="PRT",
                   latitude=41.178, longitude=-8.598, organisation_id="org-a", asset_id="b-1"),
        Mountpoint("BASE2", "Other org", organisation_id="org-b", asset_id="b-2"),
        Mountpoint("PUBLIC", "Open demo", asset_id="b-3"),
    ]  # fmt: skip


@pytest.fixture(params=["broker", "hub"])
async def caster(request: pytest.FixtureRequest) -> AsyncIterator[Caster]:
    """receiver (sim) -> RtkReader (base station) -> broker or hub -> NTRIP router on uvicorn."""
    async with running_receiver(GnssConfig(seed=21), SimClock(SPEED)) as rx:
        mps = mountpoints(rx)
        if request.param == "broker":
            broker = InProcessBroker()
            source = Source(mps, broker=broker)

            async def publish(frame: bytes) -> None:  # what the server does with a base's `rtcm`
                await broker.publish("rtcm.b-1", {"data": base64.b64encode(frame).decode()})

        else:
            hub = LiveCorrections()
            source = Source(mps, hub=hub)

            async def publish(frame: bytes) -> None:
                hub.publish("BASE1", frame)

        reader = RtkReader(RtkConfig(source=f"tcp://127.0.0.1:{rx.port}"), publish)
        reader.start()
        app = FastAPI()
        app.add_middleware(GZipMiddleware, minimum_size=16)  # as the server app has
        app.include_router(ntrip_router(source, authenticate))
        try:
            async with serve(app) as port:
                yield Caster(f"http://127.0.0.1:{port}", port, source, rx, reader)
        finally:
            await reader.stop()


def test_sourcetable_lines_follow_ntrip_v2() -> None:
    mp = Mountpoint("BASE1", "Porto; base", format_details=format_details({1005: 10, 1077: 1}),
                    country="PRT", latitude=41.178, longitude=-8.598, bitrate=4800)  # fmt: skip
    line = mp.str_line()
    fields = line.split(";")
    assert len(fields) == 19 and fields[0] == "STR" and fields[1] == "BASE1"
    assert fields[2] == "Porto, base"  # separators never leak into a field
    assert fields[3:6] == ["RTCM 3.3", "1005(10),1077(1)", "2"]
    assert fields[9:11] == ["41.18", "-8.60"]
    assert fields[15:18] == ["B", "N", "4800"]
    body = sourcetable([mp, Mountpoint("X")])
    assert body.endswith("\r\nENDSOURCETABLE\r\n") and body.count("\r\n") == 3


def test_mountpoint_names_are_url_safe() -> None:
    assert mountpoint_name("Porto Base #1") == "Porto_Base__1"
    assert mountpoint_name("base-02_x") == "base-02_x"
    assert mountpoint_name("Évora/roof") == "_vora_roof"
    assert mountpoint_name("  ") == "_"


def test_basic_auth_parsing_and_visibility() -> None:
    token = base64.b64encode(b"alice:pa:ss").decode()
    assert parse_basic_auth(f"Basic {token}") == ("alice", "pa:ss")
    assert parse_basic_auth(f"basic   {token}") == ("alice", "pa:ss")
    nocolon = base64.b64encode(b"alice").decode()
    for bad in (
        None,
        "",
        "Bearer abc",
        "Basic",
        "Basic !!!",
        f"Basic {nocolon}",
        "Basic \xe9t\xe9",
    ):
        assert parse_basic_auth(bad) is None
    mps = [Mountpoint("A", organisation_id=1), Mountpoint("B", organisation_id=2), Mountpoint("P")]
    assert [m.name for m in visible_to(mps, 1)] == ["A", "P"]
    assert [m.name for m in visible_to(mps, None)] == ["P"]


def pull_with_pygnssutils(
    port: int, mountpoint: str, user: str, password: str
) -> tuple[Any, queue.Queue[Any]]:
    out: queue.Queue[Any] = queue.Queue()
    client = GNSSNTRIPClient(retries=0, timeout=5, verbosity=0)
    client.run(server="127.0.0.1", port=port, mountpoint=mountpoint, ntripuser=user,
               ntrippassword=password, version="2.0", output=out)  # fmt: skip
    return client, out


async def test_third_party_client_receives_crc_valid_corrections(caster: Caster) -> None:
    client, out = pull_with_pygnssutils(caster.port, "ntrip/BASE1", "alice", "s3cret")
    received: list[bytes] = []
    try:

        def drain() -> bool:
            while not out.empty():
                raw, parsed = out.get_nowait()
                assert parsed.identity == str(message_type(raw))  # pygnssutils' own parse
                received.append(raw)
            return len(received) >= 24

        await eventually(drain)
    finally:
        client.stop()
    assert client.status["code"] == 200
    for raw in received:
        assert frame_ok(raw)  # CRC-24Q over the whole frame
        assert RTCMReader.parse(raw, validate=1).DF003 == 1
    assert {message_type(f) for f in received} == {1005, 1077, 1097, 1230}
    model_stream = iter(
        [f for e in range(caster.receiver.last_epoch + 1) for f in caster.receiver.model.frames(e)]
    )
    assert all(any(f == g for g in model_stream) for f in received)  # intact, in order
    await eventually(lambda: caster.source.open_subscriptions == 0)  # the subscription was released


async def test_two_clients_at_once_each_get_the_live_stream(caster: Caster) -> None:
    clients = [
        pull_with_pygnssutils(caster.port, "ntrip/BASE1", "alice", "s3cret") for _ in range(2)
    ]
    received: list[list[bytes]] = [[], []]
    try:

        def drain() -> bool:
            for (_, out), got in zip(clients, received, strict=True):
                while not out.empty():
                    got.append(out.get_nowait()[0])
            return all(len(got) >= 12 for got in received)

        await eventually(lambda: caster.source.open_subscriptions == 2)
        await eventually(drain)
    finally:
        for client, _ in clients:
            client.stop()
    for got in received:
        assert all(frame_ok(f) for f in got)
    common = set(received[0]) & set(received[1])
    assert any(message_type(f) == 1077 for f in common)  # the same epochs reached both
    await eventually(lambda: caster.source.open_subscriptions == 0)


async def test_third_party_client_reads_the_sourcetable(caster: Caster) -> None:
    client, out = pull_with_pygnssutils(caster.port, "ntrip/", "alice", "s3cret")
    try:
        await eventually(lambda: not out.empty())
        table, _closest = out.get_nowait()
    finally:
        client.stop()
    names = [row[0] for row in table]
    assert names == ["BASE1", "PUBLIC"]  # not the other organisation's base
    assert table[0][2] == "RTCM 3.3" and table[0][3] == "1005(1),1077(1),1097(1),1230(1)"


async def test_third_party_client_with_bad_credentials_gets_401(caster: Caster) -> None:
    client, out = pull_with_pygnssutils(caster.port, "ntrip/BASE1", "alice", "wrong")
    try:
        await eventually(lambda: bool(client.status) and not client.connected)
    finally:
        client.stop()
    assert client.status["code"] == 401
    assert out.empty()


def ntrip_headers(user: str | None = "alice", password: str = "s3cret") -> dict[str, str]:
    headers = {"Ntrip-Version": "Ntrip/2.0", "User-Agent": "NTRIP test", "Accept-Encoding": "gzip"}
    if user is not None:
        headers["Authorization"] = (
            "Basic " + base64.b64encode(f"{user}:{password}".encode()).decode()
        )
    return headers


async def test_stream_is_chunked_gnss_data_and_uncompressed(caster: Caster) -> None:
    async with httpx.AsyncClient(base_url=caster.url, timeout=10) as http:
        async with http.stream("GET", "/ntrip/BASE1", headers=ntrip_headers()) as r:
            assert r.status_code == 200
            assert r.headers["content-type"] == "gnss/data"
            assert r.headers["transfer-encoding"] == "chunked"
            assert r.headers["ntrip-version"] == "Ntrip/2.0"
            assert r.headers.get("content-encoding", "identity") == "identity"
            reframer, frames = Reframer(), []
            async for chunk in r.aiter_raw():
                frames.extend(reframer.feed(chunk))
                if len(frames) >= 8:
                    break
        assert reframer.bad_frames == 0 and reframer.skipped_bytes == 0
        assert all(frame_ok(f) for f in frames)
        await eventually(lambda: caster.source.open_subscriptions == 0)


async def test_errors_401_404_400_and_anonymous_sourcetable(caster: Caster) -> None:
    async with httpx.AsyncClient(base_url=caster.url, timeout=10) as http:
        r = await http.get("/ntrip/BASE1", headers=ntrip_headers(None))
        assert r.status_code == 401
        assert r.headers["www-authenticate"].startswith("Basic realm=")
        r = await http.get("/ntrip/BASE1", headers=ntrip_headers("alice", "nope"))
        assert r.status_code == 401 and r.json()["error"]["code"] == "unauthorized"
        r = await http.get(
            "/ntrip/BASE1", headers={**ntrip_headers(), "Authorization": "Basic %%%"}
        )
        assert r.status_code == 401
        latin1 = {**ntrip_headers(), "Authorization": "Basic \xe9t\xe9".encode("latin-1")}
        r = await http.get("/ntrip/BASE1", headers=latin1)  # non-ASCII: a 401, not a 500
        assert r.status_code == 401
        r = await http.get("/ntrip/NOPE", headers=ntrip_headers())
        assert r.status_code == 404 and r.json()["error"]["code"] == "not_found"
        r = await http.get("/ntrip/BASE2", headers=ntrip_headers())  # another organisation's base
        assert r.status_code == 404
        r = await http.get(
            "/ntrip/BASE1", headers={"Authorization": ntrip_headers()["Authorization"]}
        )
        assert r.status_code == 400  # no Ntrip-Version: Ntrip/2.0
        r = await http.get("/ntrip/")
        assert r.status_code == 200 and r.headers["content-type"] == "gnss/sourcetable"
        assert r.text == sourcetable([Mountpoint("PUBLIC", "Open demo")])
        r = await http.get("/ntrip", headers=ntrip_headers("bob", "hunter2"))
        assert [line.split(";")[1] for line in r.text.splitlines()[:-1]] == ["BASE2", "PUBLIC"]
        assert r.text.endswith("ENDSOURCETABLE\r\n")
        r = await http.get("/ntrip/", headers=ntrip_headers("bob", "bad"))
        assert r.status_code == 401
    assert caster.source.open_subscriptions == 0


async def test_live_corrections_fan_out_and_drop_oldest() -> None:
    hub = LiveCorrections(queue_size=2)
    a, b = hub.subscribe("M"), hub.subscribe("M")
    first_a, first_b = asyncio.ensure_future(anext(a)), asyncio.ensure_future(anext(b))
    await eventually(lambda: hub.subscribers("M") == 2)
    hub.publish("M", b"1")
    assert await first_a == b"1" and await first_b == b"1"
    for frame in (b"2", b"3", b"4"):
        hub.publish("M", frame)
    assert hub.dropped == 2  # each subscriber lost its oldest
    assert await anext(a) == b"3" and await anext(a) == b"4"
    await a.aclose()
    await b.aclose()
    assert hub.subscribers("M") == 0
    hub.publish("M", b"nobody listens")


async def test_broker_frames_skip_malformed_and_bad_crc_messages() -> None:
    broker = InProcessBroker()

    class Watched:  # the real broker, with its subscriptions counted
        handlers = 0

        def subscribe(self, channel: str, handler: Any) -> None:
            self.handlers += 1
            broker.subscribe(channel, handler)

        def unsubscribe(self, channel: str, handler: Any) -> None:
            self.handlers -= 1
            broker.unsubscribe(channel, handler)

    watched = Watched()
    frames = broker_frames(watched, "rtcm.x", queue_size=8)
    first = asyncio.ensure_future(anext(frames))
    await eventually(lambda: watched.handlers == 1)
    good = BaseStationModel(GnssConfig()).frames(0)[0]
    bad = good[:-1] + bytes([good[-1] ^ 1])
    for message in ({}, {"data": "%%%"}, {"data": base64.b64encode(bad).decode()}):
        await broker.publish("rtcm.x", message)
    await broker.publish("rtcm.x", {"data": base64.b64encode(good).decode()})
    assert await first == good
    await frames.aclose()
    assert watched.handlers == 0


async def test_a_stream_ends_when_its_check_says_no_and_goes_on_when_the_check_fails() -> None:
    async def frames() -> AsyncIterator[bytes]:
        for i in range(5):
            yield bytes([i])

    answers = iter([True, False])

    async def allowed() -> bool:
        return next(answers)

    async def broken() -> bool:
        raise ConnectionError("the database is away")

    def counted() -> dict[str, float]:  # aerobase_ntrip_rechecks_total by outcome
        name = "aerobase_ntrip_rechecks_total"
        return {
            o: REGISTRY.get_sample_value(name, {"outcome": o}) or 0.0
            for o in ("allowed", "ended", "failed")
        }

    # every_s 0: asked before each frame after the first check's moment
    before = counted()
    assert [f async for f in rechecked(frames(), allowed, 0.0)] == [b"\x00"]
    assert [f async for f in rechecked(frames(), broken, 0.0)] == [bytes([i]) for i in range(5)]
    assert [f async for f in rechecked(frames(), None, 0.0)] == [bytes([i]) for i in range(5)]
    after = counted()
    assert {o: after[o] - before[o] for o in after} == {"allowed": 1, "ended": 1, "failed": 5}
