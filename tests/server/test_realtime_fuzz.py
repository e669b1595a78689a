"""The WebSocket protocols fuzzed over real sockets (issue 14, "Done means"): binary, oversized,
non-finite, out-of-range, unknown kinds, malformed JSON, wrong types, on /ws/asset and /ws/operator.

A seeded generator mutates valid messages. The oracle is the protocol's own decoder: every
message it refuses must be answered by an `error` with its code (or the documented close code),
every durable message it accepts must be acknowledged, and the server must log no error and no
unhandled exception. After each message a probe (a message of an unknown kind, which always gets
`unknown_kind`) marks where that message's replies end.
"""

from __future__ import annotations

import asyncio
import copy
import json
import logging
import random
import uuid
from collections.abc import Iterator
from typing import Any

import httpx
import pytest
import websockets
from websockets.asyncio.client import ClientConnection

from protocol.base import MAX_MESSAGE_BYTES
from protocol.codec import DecodeError, decode, drop_non_finite
from protocol.messages import now_ms
from tests.conftest import LiveServer, Tenant, test_settings
from tests.polling import eventually
from tests.server.realtime_client import asset_token, hello, ws_url

pytestmark = pytest.mark.slow  # about 5 s for both sockets

SEED = 14
MESSAGES = 250  # per socket
DURABLE = ("telemetry", "event", "command_result")
PROBE_SEQ = 7_000_000_000_000  # in range; marks the probe's error


@pytest.fixture(scope="module")
def server(database_url: str) -> Iterator[LiveServer]:
    """A server whose rate limits are out of the way: the fuzz checks answers, not pacing."""
    settings = test_settings(
        database_url, ws_rate_per_s=100_000.0, ws_burst=100_000.0,
        ws_operator_rate_per_s=100_000.0, ws_operator_burst=100_000.0,
    )  # fmt: skip
    live = LiveServer(settings).start()
    yield live
    live.stop()


NASTY: list[Any] = [
    None, True, False, -1, 0, 1, 2**31, 2**53, 2**63, 2**64, 10**30, -(10**30), 1.5, -0.0,
    float("nan"), float("inf"), float("-inf"), "", "x", "é\u2028", "\x00", "a" * 5000,
    [], {}, [1, "a"], {"a": float("nan")}, {"nested": {"deeper": [None, 2**70]}},
    "6f1c3a3e-58a4-4d1e-9f55-000000000001", "not-a-uuid", 1_767_225_600_000, 10**17,
]  # fmt: skip
KINDS = ["hello", "telemetry", "event", "command_result", "rtcm", "error", "ack", "welcome",
         "command", "subscribe", "unsubscribe", "run_progress", "teleport", "", "TELEMETRY"]  # fmt: skip


def templates(asset_id: str) -> list[dict[str, Any]]:
    """Valid messages of each kind either socket takes."""
    return [
        {"type": "telemetry", "payload": {
            "kind": "uav", "armed": True, "flight_mode": "AUTO", "heading_deg": 90.0,
            "position": {"lat": 41.0, "lon": -8.6, "alt_msl_m": 120.0, "alt_rel_m": 20.0},
            "attitude": {"roll_deg": 1.0, "pitch_deg": 2.0, "yaw_deg": 3.0},
            "battery": {"percent": 80.0, "voltage_v": 16.0}, "mission": {"current": 1, "total": 3},
            "gnss": {"fix": "rtk_fixed", "satellites": 20, "hdop": 0.6}}},
        {"type": "telemetry", "payload": {
            "kind": "landing_base", "plc_link": "up", "scale_mass_g": 1200.0,
            "panels": {"state": "open", "position_pct": 100.0},
            "weather": {"wind_m_s": 3.0, "temperature_c": 12.0}, "faults": {"bits": 16}}},
        {"type": "event", "payload": {"name": "armed", "severity": "info", "message": "motors armed",
                                      "data": {"index": 3, "x": [1.5, "a"]}}},
        {"type": "command_result", "re": str(uuid.uuid4()), "payload": {
            "status": "in_progress", "reason": "", "data": {"a": 1},
            "progress": {"step": "panels", "index": 1, "total": 2}}},
        {"type": "rtcm", "payload": {"data": "0wAAR3rP"}},
        {"type": "subscribe", "payload": {"asset_ids": [asset_id, str(uuid.uuid4())]}},
        {"type": "unsubscribe", "payload": {"asset_ids": [asset_id]}},
        {"type": "error", "payload": {"code": "oops", "message": "client side"}},
        {"type": "hello", "payload": {"stream": str(uuid.uuid4()), "agent": "asset_agent",
                                      "version": "x"}},
    ]  # fmt: skip


def _paths(node: Any, prefix: tuple[Any, ...] = ()) -> list[tuple[Any, ...]]:
    out = [prefix] if prefix else []
    if isinstance(node, dict):
        for key, value in node.items():
            out += _paths(value, (*prefix, key))
    elif isinstance(node, list):
        for index, value in enumerate(node):
            out += _paths(value, (*prefix, index))
    return out


def _mutate(rng: random.Random, msg: dict[str, Any]) -> None:
    paths = _paths(msg)
    path = rng.choice(paths)
    parent: Any = msg
    for part in path[:-1]:
        parent = parent[part]
    roll = rng.random()
    if roll < 0.6:
        parent[path[-1]] = copy.deepcopy(rng.choice(NASTY))
    elif roll < 0.75 and isinstance(parent, dict):
        parent.pop(path[-1])
    elif roll < 0.85 and isinstance(parent, dict):
        parent[rng.choice(["extra", "kind", "asset_id", "seq"])] = copy.deepcopy(rng.choice(NASTY))
    else:
        msg["type"] = rng.choice(KINDS)


def fuzz_texts(rng: random.Random, asset_id: str, seq: list[int]) -> Iterator[str | bytes]:
    """Frames to send: mostly mutated messages, some raw garbage, now and then a close case."""
    for _ in range(MESSAGES):
        roll = rng.random()
        if roll < 0.02:
            yield rng.randbytes(rng.randint(0, 64))  # binary: close 1003
            continue
        if roll < 0.04:
            yield '{"v": 1, "pad": "' + "x" * MAX_MESSAGE_BYTES + '"}'  # oversize: close 1009
            continue
        if roll < 0.10:
            yield rng.choice(
                [
                    "{not json",
                    '{"v": 1, "type": "telemetry", ',
                    "[" * 5000 + "]" * 5000,
                    '{"a":' * 300 + "1" + "}" * 300,
                    "".join(chr(rng.randint(1, 0x2FFF)) for _ in range(40)),
                    "null",
                    "42",
                    '"text"',
                ]
            )
            continue
        msg = copy.deepcopy(rng.choice(templates(asset_id)))
        seq[0] += 1
        msg = {
            "v": 1,
            "id": str(uuid.uuid4()),
            "seq": seq[0],
            "ts": now_ms(),
            **msg,
        }
        for _ in range(rng.choice([0, 1, 1, 2, 3])):
            _mutate(rng, msg)
        yield json.dumps(msg)


def probe() -> str:
    return json.dumps(
        {"v": 1, "type": "probe", "id": str(uuid.uuid4()), "seq": PROBE_SEQ, "ts": 0, "payload": {}}
    )


def expected(text: str | bytes, direction: str) -> tuple[set[str], bool, int | None]:
    """(error codes the server must answer, whether an ack must come, the close code if any)."""
    if isinstance(text, bytes):
        return set(), False, 1003
    if len(text.encode()) > MAX_MESSAGE_BYTES:
        return set(), False, 1009
    msg = decode(text, direction)  # type: ignore[arg-type]
    if isinstance(msg, DecodeError):
        salvaged = (
            drop_non_finite(text, direction)  # type: ignore[arg-type]
            if direction == "asset_to_server"
            and msg.code == "invalid_payload"
            and msg.kind in DURABLE
            else None
        )
        return {msg.code}, salvaged is not None, None
    if direction == "asset_to_server":
        if msg.type == "hello":
            return {"unexpected_hello"}, False, None
        return set(), msg.type in DURABLE, None
    return set(), False, None


async def replies_until_probe(
    ws: ClientConnection, want_ack: bool
) -> tuple[list[dict[str, Any]], int | None]:
    """Replies up to the probe's error (and up to an ack when one is due); the close code if closed."""
    got: list[dict[str, Any]] = []
    seen_probe = False
    try:
        async with asyncio.timeout(15):
            while not seen_probe or (want_ack and not any(m["type"] == "ack" for m in got)):
                reply = json.loads(await ws.recv())
                if reply["type"] == "error" and reply["payload"].get("re_seq") == PROBE_SEQ:
                    seen_probe = True
                    continue
                got.append(reply)
    except websockets.ConnectionClosed as closed:
        return got, closed.rcvd.code if closed.rcvd else None
    return got, None


def server_errors(caplog: pytest.LogCaptureFixture) -> list[str]:
    """Every error, and every record carrying an exception, logged so far (server threads too)."""
    return [
        f"{r.name}: {r.getMessage()}"
        for r in caplog.records
        if r.levelno >= logging.ERROR or r.exc_info
    ]


async def _fuzz(
    server: LiveServer, direction: str, connect: Any, asset_id: str, seed: int
) -> dict[str, int]:
    rng = random.Random(seed)
    seq = [0]
    tally: dict[str, int] = {}
    ws = await connect()
    try:
        for text in fuzz_texts(rng, asset_id, seq):
            codes, want_ack, close = expected(text, direction)
            try:
                await ws.send(text)
            except websockets.ConnectionClosed:
                # a message over the size limit: the server may close on the frame's header
                # while the rest of it is still being written (_closed reads the code then too)
                assert close is not None, text[:200]
            if close is not None:
                code = await _closed(ws)
                assert code == close, (text[:200], code)
                tally[f"close {close}"] = tally.get(f"close {close}", 0) + 1
                ws = await connect()
                continue
            await ws.send(probe())
            got, closed_with = await replies_until_probe(ws, want_ack)
            assert closed_with is None, (text[:300], closed_with, got)
            errors = {m["payload"]["code"] for m in got if m["type"] == "error"} - {"not_found"}
            assert errors == codes, (text[:300], got)
            assert want_ack == any(m["type"] == "ack" for m in got), (text[:300], got)
            for code in codes or {"accepted"}:
                tally[code] = tally.get(code, 0) + 1
    finally:
        await ws.close()
    return tally


async def _closed(ws: ClientConnection) -> int | None:
    try:
        async with asyncio.timeout(10):
            while True:
                await ws.recv()
    except websockets.ConnectionClosed as closed:
        return closed.rcvd.code if closed.rcvd else None


async def test_fuzz_the_asset_socket(
    server: LiveServer, superuser_email: str, caplog: pytest.LogCaptureFixture
) -> None:
    caplog.set_level(logging.WARNING)
    tenant = Tenant(httpx.Client(base_url=server.url, timeout=30), superuser_email)
    uav = tenant.create_asset("uav")

    async def connect() -> ClientConnection:
        async def opened() -> ClientConnection | None:
            ws = await websockets.connect(
                ws_url(server.url, "/ws/asset", asset_token(server.url, uav)), max_size=None
            )
            await ws.send(hello())
            try:
                reply = json.loads(await asyncio.wait_for(ws.recv(), 10))
            except websockets.ConnectionClosed:
                return None  # the last socket's presence not yet released (4409)
            assert reply["type"] == "welcome", reply
            return ws

        return await eventually(opened, 15, "a new asset socket")  # type: ignore[no-any-return]

    tally = await _fuzz(server, "asset_to_server", connect, uav["id"], SEED)
    assert server_errors(caplog) == []
    # the generator reached every kind of answer
    assert {"malformed_json", "invalid_envelope", "invalid_payload", "unknown_kind",
            "unexpected_kind", "accepted", "close 1003", "close 1009"} <= set(tally), tally  # fmt: skip


async def test_fuzz_the_operator_socket(
    server: LiveServer, superuser_email: str, caplog: pytest.LogCaptureFixture
) -> None:
    caplog.set_level(logging.WARNING)
    tenant = Tenant(httpx.Client(base_url=server.url, timeout=30), superuser_email)
    uav = tenant.create_asset("uav")

    async def connect() -> ClientConnection:
        ws = await websockets.connect(
            ws_url(server.url, "/ws/operator", tenant.tokens["viewer"]), max_size=None
        )
        await ws.send(json.dumps({"v": 1, "type": "subscribe", "id": str(uuid.uuid4()), "seq": 0,
                                  "ts": 0, "payload": {"asset_ids": []}}))  # fmt: skip
        return ws

    tally = await _fuzz(server, "operator_to_server", connect, uav["id"], SEED + 1)
    assert server_errors(caplog) == []
    assert {"malformed_json", "invalid_envelope", "invalid_payload", "unknown_kind",
            "unexpected_kind", "accepted", "close 1003", "close 1009"} <= set(tally), tally  # fmt: skip
