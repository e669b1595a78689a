"""A raw WebSocket client for the server's sockets, for tests that send what no real client would."""

from __future__ import annotations

import asyncio
import base64
import json
import uuid
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from typing import Any

import httpx
import websockets
from websockets.asyncio.client import ClientConnection

from assetlink.configfile import decrypt_config
from protocol.messages import now_ms


def message(kind: str, payload: Any, seq: int = 0, ts: int | None = None) -> str:
    """One envelope's JSON text, sent now by default (Python's encoder: NaN and Infinity stay)."""
    return json.dumps(
        {
            "v": 1,
            "type": kind,
            "id": str(uuid.uuid4()),
            "seq": seq,
            "ts": now_ms() if ts is None else ts,
            "payload": payload,
        }
    )


def hello(stream: uuid.UUID | None = None) -> str:
    """A daemon's hello on a stream (a fresh one by default)."""
    return message(
        "hello",
        {"stream": str(stream or uuid.uuid4()), "agent": "asset_agent", "version": "test"},
    )


def uav_sample(i: int = 0, **extra: Any) -> dict[str, Any]:
    """A UAV telemetry payload."""
    return {
        "kind": "uav",
        "position": {"lat": 41.0 + i * 1e-6, "lon": -8.6, "alt_msl_m": 120.0, "alt_rel_m": 5.0},
        "armed": False,
        **extra,
    }


def asset_token(server_url: str, asset: dict[str, Any]) -> str:
    """Log the asset in (name and secret from its config file) and return its session token."""
    cfg = decrypt_config(base64.b64decode(asset["config_file"]), "asset-password-123")
    r = httpx.post(
        f"{server_url}/api/v1/assets/login",
        json={"name": cfg.name, "secret": cfg.secret, "force": True},
    )
    assert r.status_code == 200, r.text
    return str(r.json()["access_token"])


def ws_url(server_url: str, path: str, token: str | None = None) -> str:
    """The ws:// URL of a socket, with `?token=` when given."""
    url = server_url.replace("http", "ws", 1) + path
    return f"{url}?token={token}" if token else url


@asynccontextmanager
async def asset_socket(server_url: str, token: str, **kw: Any) -> AsyncIterator[ClientConnection]:
    """An asset socket past hello/welcome."""
    async with websockets.connect(ws_url(server_url, "/ws/asset", token), **kw) as ws:
        await ws.send(hello())
        welcome = json.loads(await asyncio.wait_for(ws.recv(), 10))
        assert welcome["type"] == "welcome", welcome
        yield ws


@asynccontextmanager
async def operator_socket(
    server_url: str, token: str, follow: tuple[str, ...] = ()
) -> AsyncIterator[ClientConnection]:
    """An operator socket the server is serving, following `follow`: its subscribe also names an
    unknown id, whose not_found is sent once the known ones are followed, and is awaited."""
    async with websockets.connect(ws_url(server_url, "/ws/operator", token)) as ws:
        await ws.send(message("subscribe", {"asset_ids": [*follow, str(uuid.uuid4())]}, ts=0))
        answer = json.loads(await asyncio.wait_for(ws.recv(), 10))
        assert answer["type"] == "error" and answer["payload"]["code"] == "not_found", answer
        yield ws


async def next_of(ws: ClientConnection, *kinds: str, within: float = 10.0) -> dict[str, Any]:
    """The next message of one of these kinds (others are skipped)."""
    async with asyncio.timeout(within):
        while True:
            msg = json.loads(await ws.recv())
            if msg["type"] in kinds:
                return dict(msg)


async def close_code(ws: ClientConnection, within: float = 10.0) -> int | None:
    """Read until the server closes the socket; its close code (None: closed without a frame)."""
    try:
        async with asyncio.timeout(within):
            while True:
                await ws.recv()
    except websockets.ConnectionClosed as closed:
        return closed.rcvd.code if closed.rcvd else None
