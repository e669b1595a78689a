"""Our side of the telemetry benchmark: one `aerobase server` process, set up through the public API.

The server runs as a subprocess with its own SQLite file (or DATABASE_URL) and the in-process
broker. A superuser comes from `aerobase admin create-superuser` on the same database; the
organisation, one viewer per operator and the UAV assets are created over HTTP; assets log in with
the secret of their encrypted configuration file and speak `/ws/asset`; operators watch every asset
over `/ws/operator`.
"""

from __future__ import annotations

import asyncio
import base64
import contextlib
import json
import os
import resource
import subprocess
import sys
import time
import uuid
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import httpx
import msgspec
import orjson

from aerobase.ports import free_port
from assetlink.configfile import decrypt_config
from bench import _lean as lean
from bench._lean import LeanSocket
from bench._load import Payloads, Recorder, drain, figures, mark, pace, process_cpu
from protocol.codec import encode
from protocol.messages import HelloPayload, envelope


class _Asset(msgspec.Struct):
    asset_id: str = ""


class _Delivered(msgspec.Struct):
    """What an operator's reader needs of a message (the rest is skipped, not parsed: a full
    JSON parse of 20,000 telemetry messages a second was most of the generator's CPU)."""

    type: str
    seq: int = 0
    payload: _Asset | None = None


_DELIVERED = msgspec.json.Decoder(_Delivered)

ROOT = Path(__file__).resolve().parents[1]
SUPER_PASSWORD = "bench-superuser-password-1"
USER_PASSWORD = "bench-viewer-password-1"
ASSET_PASSWORD = "bench-asset-password-1"
IDLE_S = 5.0  # seconds of idle CPU measured with every socket connected, before the load

Progress = Callable[[str], None]


def raise_fd_limit() -> int:
    """Raise this process's open-file limit to its hard limit (children inherit it)."""
    soft, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
    if soft < hard:
        resource.setrlimit(resource.RLIMIT_NOFILE, (hard, hard))
    return resource.getrlimit(resource.RLIMIT_NOFILE)[0]


@dataclass
class Server:
    """A running `aerobase server` subprocess."""

    proc: subprocess.Popen
    url: str
    database_url: str
    log_path: Path

    @property
    def pid(self) -> int:
        """The server's process id."""
        return self.proc.pid

    def stop(self) -> None:
        """Terminate the server (SIGTERM, then SIGKILL after 15 s)."""
        if self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(15)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait(5)


def server_env(database_url: str, port: int, root: Path = ROOT) -> dict[str, str]:
    """The environment of the benchmark's server: fast set-up, no throttling of the load."""
    return {
        **os.environ,
        "DATABASE_URL": database_url,
        "AEROBASE_PORT": str(port),
        "AEROBASE_CONFIG_SCRYPT_LOG_N": "12",
        "AEROBASE_WS_RATE_PER_S": "1000000",
        "AEROBASE_WS_BURST": "1000000",
        "AEROBASE_LOGIN_MAX_FAILURES_ADDRESS": "100000",
        "AEROBASE_ARGON2_MEMORY_KIB": "8192",
        "AEROBASE_ARGON2_TIME_COST": "1",
        "AEROBASE_ARGON2_PARALLELISM": "1",
        "AEROBASE_LOG_FORMAT": "json",
        "PYTHONPATH": str(root),
    }


def start_server(tmp: Path, superuser: str, progress: Progress, root: Path = ROOT) -> Server:
    """Create the superuser on the database, start `aerobase server` (of the checkout at `root`,
    by default this one), wait for /api/health."""
    database_url = os.environ.get("DATABASE_URL") or f"sqlite+aiosqlite:///{tmp}/bench.db"
    port = free_port()
    env = server_env(database_url, port, root)
    cli = [sys.executable, "-m", "aerobase.cli"]
    progress(f"creating the superuser on {database_url.split('@')[-1]}")
    done = subprocess.run(
        [*cli, "admin", "create-superuser", "--email", superuser, "--password", SUPER_PASSWORD],
        env=env,
        cwd=root,
        capture_output=True,
        text=True,
        timeout=120,
    )
    if done.returncode != 0:
        raise RuntimeError(f"aerobase admin create-superuser failed: {done.stderr.strip()[-500:]}")
    log_path = tmp / "server.log"
    log = open(log_path, "wb")
    proc = subprocess.Popen(
        [*cli, "server", "--port", str(port)],
        env=env,
        cwd=root,
        stdout=log,
        stderr=subprocess.STDOUT,
    )
    server = Server(proc, f"http://127.0.0.1:{port}", database_url, log_path)
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline:
        if proc.poll() is not None:
            raise RuntimeError(f"aerobase server exited with {proc.returncode}; see {log_path}")
        with contextlib.suppress(httpx.HTTPError):
            if httpx.get(f"{server.url}/api/health", timeout=1).status_code == 200:
                progress(f"aerobase server pid {proc.pid} is up on {server.url}")
                return server
        time.sleep(0.1)
    server.stop()
    raise RuntimeError("aerobase server did not answer /api/health within 60 s")


@dataclass
class Fleet:
    """What set-up produced: asset ids, names and secrets, and one viewer token per operator."""

    asset_ids: list[str]
    names: list[str]
    secrets: list[str]
    viewer_tokens: list[str]
    viewer_emails: list[str] = field(default_factory=list)  # each with USER_PASSWORD


def _ok(r: httpx.Response, expected: int = 200) -> dict:
    if r.status_code != expected:
        raise RuntimeError(
            f"{r.request.method} {r.request.url.path} answered {r.status_code}: {r.text[:300]}"
        )
    return dict(r.json())


async def set_up(
    url: str,
    superuser: str,
    assets: int,
    operators: int,
    progress: Progress,
    base_at: tuple[float, float] | None = None,
) -> Fleet:
    """Organisation, viewers and UAV assets through the public API; with `base_at` (latitude,
    longitude) also a landing base surveyed there (the console draws the UAVs' maps around it)."""
    async with httpx.AsyncClient(base_url=url, timeout=120) as api:
        login = {"email": superuser, "password": SUPER_PASSWORD, "force": True}
        root = _ok(await api.post("/api/v1/auth/login", json=login))["access_token"]
        org = _ok(
            await api.post(
                "/api/v1/organizations",
                json={"name": f"bench-{uuid.uuid4().hex[:8]}"},
                headers={"Authorization": f"Bearer {root}"},
            ),
            201,
        )
        root = _ok(
            await api.post("/api/v1/auth/login", json={**login, "organization_id": org["id"]})
        )["access_token"]
        h = {"Authorization": f"Bearer {root}"}
        tokens, emails = [], []
        for k in range(operators):
            email = f"viewer-{k}-{uuid.uuid4().hex[:6]}@bench.test"
            emails.append(email)
            _ok(
                await api.post(
                    "/api/v1/users",
                    json={"email": email, "password": USER_PASSWORD, "role": "viewer"},
                    headers=h,
                ),
                201,
            )
            tokens.append(
                _ok(
                    await api.post(
                        "/api/v1/auth/login", json={"email": email, "password": USER_PASSWORD}
                    )
                )["access_token"]
            )
        if base_at is not None:
            base = {
                "name": f"bench-base-{uuid.uuid4().hex[:6]}",
                "kind": "landing_base",
                "password": ASSET_PASSWORD,
                "attributes": {"latitude": base_at[0], "longitude": base_at[1]},
            }
            _ok(await api.post("/api/v1/assets", json=base, headers=h), 201)
        ids, names, secrets = [""] * assets, [""] * assets, [""] * assets
        tag, counter, lock = uuid.uuid4().hex[:6], iter(range(assets)), asyncio.Lock()
        registered = 0

        async def worker() -> None:
            nonlocal registered
            for i in counter:
                body = {
                    "name": f"bench-uav-{tag}-{i:05d}",
                    "kind": "uav",
                    "password": ASSET_PASSWORD,
                    "description": "telemetry benchmark",
                }
                created = _ok(await api.post("/api/v1/assets", json=body, headers=h), 201)
                cfg = await asyncio.to_thread(
                    decrypt_config, base64.b64decode(created["config_file"]), ASSET_PASSWORD
                )
                ids[i], names[i], secrets[i] = created["id"], cfg.name, cfg.secret
                async with lock:
                    registered += 1
                    if registered % 100 == 0 or registered == assets:
                        progress(f"registered {registered}/{assets} assets")

        await asyncio.gather(*(worker() for _ in range(min(8, assets))))
        return Fleet(ids, names, secrets, tokens, emails)


def _ws(url: str) -> str:
    return url.replace("http://", "ws://", 1).replace("https://", "wss://", 1)


async def _operator(
    url: str, token: str, asset_ids: list[str], on_text: Callable[[bytes], None]
) -> LeanSocket:
    """Connect a viewer to /ws/operator and subscribe to every asset; returns once subscribed.
    From then on `on_text` hears every message."""
    probe = str(uuid.uuid4())
    subscribed: asyncio.Future[None] = asyncio.get_running_loop().create_future()

    def during_subscribe(raw: bytes) -> None:
        # The server handles an operator's messages in order: the error for an unknown asset
        # id, asked for next, proves the first subscription is in place.
        if b'"type":"error"' in raw and not subscribed.done():
            if probe.encode() in raw:
                subscribed.set_result(None)
            else:
                subscribed.set_exception(RuntimeError(f"subscribe failed: {raw[:300]!r}"))
        elif subscribed.done():
            on_text(raw)

    ws = await lean.connect(url, f"/ws/operator?token={token}", during_subscribe)
    subscribe = {"v": 1, "type": "subscribe", "id": str(uuid.uuid4()), "seq": 0, "ts": 0}
    ws.send(json.dumps({**subscribe, "payload": {"asset_ids": asset_ids}}))
    ws.send(json.dumps({**subscribe, "id": str(uuid.uuid4()), "payload": {"asset_ids": [probe]}}))
    await asyncio.wait_for(subscribed, 120)
    ws.on_text = on_text
    return ws


async def _asset(
    url: str, name: str, secret: str, api: httpx.AsyncClient, on_text: Callable[[bytes], None]
) -> LeanSocket:
    """Log an asset in and open its /ws/asset session (hello, welcome); `on_text` then hears
    its acks and errors."""
    token = _ok(
        await api.post("/api/v1/assets/login", json={"name": name, "secret": secret, "force": True})
    )
    welcome: asyncio.Future[bytes] = asyncio.get_running_loop().create_future()

    def first(raw: bytes) -> None:
        if not welcome.done():
            welcome.set_result(raw)

    ws = await lean.connect(
        url, "/ws/asset", first, {"Authorization": f"Bearer {token['access_token']}"}
    )
    ws.send(
        encode(envelope(HelloPayload(stream=uuid.uuid4(), agent="asset_agent", version="0.1.0")))
    )
    answer = orjson.loads(await asyncio.wait_for(welcome, 60))
    if answer.get("type") != "welcome" or answer["payload"]["last_acked_seq"] != 0:
        ws.close()
        raise RuntimeError(f"expected welcome with last_acked_seq 0, got {answer}")
    ws.on_text = on_text
    return ws


class _Ack(msgspec.Struct):
    seq: int = 0


class _Reply(msgspec.Struct):
    """What an asset's reader needs of the server's messages (acks, errors)."""

    type: str
    payload: _Ack | None = None


_REPLY = msgspec.json.Decoder(_Reply)


def ack_reader(acked: Any, index: int, errors: list[int]) -> Callable[[bytes], None]:
    """`on_text` of asset `index`: its highest ack into `acked[index]`, errors counted."""

    def on_text(raw: bytes) -> None:
        reply = _REPLY.decode(raw)
        if reply.type == "ack" and reply.payload is not None:
            if reply.payload.seq > acked[index]:
                acked[index] = reply.payload.seq
        elif reply.type == "error":
            errors[0] += 1

    return on_text


def delivery_reader(rec: Recorder, operator: int, index: dict[str, int]) -> Callable[[bytes], None]:
    """`on_text` of an operator: each telemetry delivery timed on arrival."""

    def on_text(raw: bytes) -> None:
        t = time.perf_counter()
        msg = _DELIVERED.decode(raw)
        if msg.type == "telemetry" and msg.payload is not None:
            rec.on_delivered(operator, index[msg.payload.asset_id], msg.seq, t)

    return on_text


async def run_ours(
    url: str,
    pid: int,
    fleet: Fleet,
    payloads: Payloads,
    rate: float,
    warmup: float,
    seconds: float,
    progress: Progress,
    procs: int = 1,
) -> dict:
    """Operators subscribe, assets connect, the load runs; returns the figures. With `procs` > 1
    the assets are driven by that many helper processes (bench/_fleet.py), the operators stay
    here."""
    if procs > 1:
        return await _run_ours_helpers(url, pid, fleet, rate, warmup, seconds, progress, procs)
    n, m = len(fleet.asset_ids), len(fleet.viewer_tokens)
    index = {a: i for i, a in enumerate(fleet.asset_ids)}
    rec = Recorder(n, m)
    ops = [
        await _operator(url, token, fleet.asset_ids, delivery_reader(rec, k, index))
        for k, token in enumerate(fleet.viewer_tokens)
    ]
    progress(f"{m} operator(s) subscribed to {n} assets")
    sockets: list[LeanSocket | None] = [None] * n
    errors = [0]
    async with httpx.AsyncClient(base_url=url, timeout=120) as api:
        sem = asyncio.Semaphore(32)
        connected = 0

        async def open_one(i: int) -> None:
            nonlocal connected
            async with sem:
                sockets[i] = await _asset(
                    url, fleet.names[i], fleet.secrets[i], api, ack_reader(rec.acked, i, errors)
                )
            connected += 1
            if connected % 100 == 0 or connected == n:
                progress(f"connected {connected}/{n} assets")

        await asyncio.gather(*(open_one(i) for i in range(n)))
    ws_all = [s for s in sockets if s is not None]
    idle = await idle_cpu(pid, IDLE_S)
    progress(
        f"server CPU with {n} assets and {m} operator(s) connected, no telemetry: {idle:.1f} % of a core"
    )

    def send(i: int, seq: int) -> None:
        ws_all[i].send(payloads.text(i, seq))

    try:
        marks = await pace(n, rate, warmup, seconds, rec, send, progress, pid)
        drained = await drain(rec, 15.0)
        marks["end"] = mark(rec, pid)
    finally:
        closed = closed_codes([*ws_all, *ops])
        for ws in [*ws_all, *ops]:
            ws.close()
    rec.errors += errors[0]
    result = figures(rec, marks, drained)
    result["idle_cpu_pct_of_core"] = round(idle, 1)
    result["sockets_closed_by_server"] = closed
    return result


def closed_codes(sockets: list[LeanSocket]) -> dict[str, int]:
    """How many of these sockets the server closed, by close code (before we closed any)."""
    codes: dict[str, int] = {}
    for ws in sockets:
        if ws.close_code is not None:
            codes[str(ws.close_code)] = codes.get(str(ws.close_code), 0) + 1
    return codes


async def idle_cpu(pid: int, seconds: float) -> float:
    """Percent of one core the process `pid` uses over `seconds` while we send nothing."""
    c0, t0 = process_cpu(pid), time.perf_counter()
    await asyncio.sleep(seconds)
    c1, t1 = process_cpu(pid), time.perf_counter()
    return 0.0 if c0 is None or c1 is None else 100 * (c1 - c0) / (t1 - t0)


async def _run_ours_helpers(
    url: str,
    pid: int,
    fleet: Fleet,
    rate: float,
    warmup: float,
    seconds: float,
    progress: Progress,
    procs: int,
) -> dict:
    """`run_ours` with the assets in `procs` helper processes."""
    from bench._fleet import Shared, SharedRecorder, merge_reports, slots_for, start_helpers

    n, m = len(fleet.asset_ids), len(fleet.viewer_tokens)
    index = {a: i for i, a in enumerate(fleet.asset_ids)}
    shared = Shared.create(n, slots_for(rate, warmup, seconds))
    rec = SharedRecorder(n, m, shared)
    helpers = None
    ops: list[LeanSocket] = []
    try:
        ops = [
            await _operator(url, token, fleet.asset_ids, delivery_reader(rec, k, index))
            for k, token in enumerate(fleet.viewer_tokens)
        ]
        progress(f"{m} operator(s) subscribed to {n} assets")
        helpers = start_helpers(
            procs, url, fleet.names, fleet.secrets, shared, rate, warmup, seconds
        )
        rec.helper_pids = helpers.pids()
        connected = await asyncio.to_thread(helpers.gather)
        progress(f"connected {sum(c[1] for c in connected)}/{n} assets in {procs} processes")
        idle = await idle_cpu(pid, IDLE_S)
        progress(
            f"server CPU with {n} assets and {m} operator(s) connected, no telemetry: "
            f"{idle:.1f} % of a core"
        )
        start = time.perf_counter() + 1.0
        helpers.broadcast(start)
        marks = await pace(0, rate, warmup, seconds, rec, lambda i, s: None, progress, pid, start)
        drained = await drain(rec, 15.0)
        marks["end"] = mark(rec, pid)
        helpers.broadcast("stop")
        closed = closed_codes(ops)
        for code, count in merge_reports(await asyncio.to_thread(helpers.gather), rec).items():
            closed[code] = closed.get(code, 0) + count
        result = figures(rec, marks, drained)
    finally:
        for ws in ops:
            ws.close()
        if helpers is not None:
            await asyncio.to_thread(helpers.stop)
        rec.release()
        shared.close()
    result["idle_cpu_pct_of_core"] = round(idle, 1)
    result["sockets_closed_by_server"] = {k: v for k, v in closed.items() if k != "1000"}
    result["generator_processes"] = procs + 1
    return result
