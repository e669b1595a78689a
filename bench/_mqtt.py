"""The reference side of the telemetry benchmark: Mosquitto relaying the same envelopes over MQTT.

paho-mqtt runs on the benchmark's asyncio loop through its external-loop API (the socket callbacks
drive `loop.add_reader` / `loop.add_writer`, which call `loop_read` / `loop_write`; a task calls
`loop_misc` every second), as in paho's asyncio example. N publishers, one per asset, publish on
`aerobase/<asset>/telemetry`; M subscribers listen on `aerobase/+/telemetry`.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import socket
import subprocess
import time
import uuid
from collections.abc import Callable

import paho.mqtt.client as mqtt

from bench._load import Payloads, Recorder, drain, figures, mark, pace

Progress = Callable[[str], None]


def mosquitto_pid() -> int | None:
    """The pid of the local mosquitto process (`pgrep -x mosquitto`), None when there is none."""
    try:
        out = subprocess.run(
            ["pgrep", "-x", "mosquitto"], capture_output=True, text=True, timeout=5
        ).stdout
    except (OSError, subprocess.SubprocessError):
        return None
    pids = [int(p) for p in out.split()]
    return pids[0] if pids else None


def mosquitto_nodelay(pid: int | None) -> bool | None:
    """Whether mosquitto `pid` runs with `set_tcp_nodelay true` (read from its -c file); None if unknown."""
    if pid is None:
        return None
    try:
        with open(f"/proc/{pid}/cmdline", "rb") as f:
            argv = f.read().decode().split("\0")
        conf = argv[argv.index("-c") + 1]
        with open(conf) as f:
            lines = [
                line.split() for line in f if line.strip() and not line.lstrip().startswith("#")
            ]
    except (OSError, ValueError, IndexError):
        return None
    values = [
        words[1].lower() == "true"
        for words in lines
        if len(words) > 1 and words[0] == "set_tcp_nodelay"
    ]
    return values[-1] if values else False  # mosquitto's default is false (Nagle on)


def reachable(host: str, port: int) -> bool:
    """True when a TCP connection to host:port succeeds."""
    try:
        with socket.create_connection((host, port), timeout=1):
            return True
    except OSError:
        return False


class AsyncMqtt:
    """One paho client driven by the running asyncio loop."""

    def __init__(self, loop: asyncio.AbstractEventLoop, client_id: str) -> None:
        self.loop = loop
        self.client = mqtt.Client(
            mqtt.CallbackAPIVersion.VERSION2, client_id=client_id, protocol=mqtt.MQTTv311
        )
        self.client.max_inflight_messages_set(1000)
        self.client.max_queued_messages_set(0)
        self.connected = loop.create_future()
        self.packets = 0  # callbacks seen: lets the reader drain several packets per wake-up
        self._misc: asyncio.Task[None] | None = None
        c = self.client
        c.on_socket_open = self._open
        c.on_socket_close = self._close
        c.on_socket_register_write = lambda _c, _u, sock: loop.add_writer(sock, self._writable)
        c.on_socket_unregister_write = lambda _c, _u, sock: loop.remove_writer(sock)
        c.on_connect = self._on_connect

    def _open(self, _c: mqtt.Client, _u: object, sock: socket.socket) -> None:
        self.loop.add_reader(sock, self._readable)
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_SNDBUF, 1 << 20)
        self._misc = self.loop.create_task(self._misc_loop())

    def _close(self, _c: mqtt.Client, _u: object, sock: socket.socket) -> None:
        self.loop.remove_reader(sock)
        self.loop.remove_writer(sock)
        if self._misc:
            self._misc.cancel()

    def _readable(self) -> None:
        # paho reads one packet per loop_read; keep reading while packets keep arriving.
        for _ in range(256):
            before = self.packets
            self.client.loop_read()
            if self.packets == before:
                break

    def _writable(self) -> None:
        self.client.loop_write()

    async def _misc_loop(self) -> None:
        while self.client.loop_misc() == mqtt.MQTT_ERR_SUCCESS:  # noqa: ASYNC110 - paho timer
            await asyncio.sleep(1)

    def _on_connect(
        self, _c: mqtt.Client, _u: object, _f: object, reason: object, _p: object
    ) -> None:
        self.packets += 1
        if not self.connected.done():
            self.connected.set_result(reason)

    async def connect(self, host: str, port: int) -> None:
        """Open the TCP connection and wait for CONNACK."""
        self.client.connect(host, port, keepalive=60)
        reason = await asyncio.wait_for(self.connected, 30)
        if getattr(reason, "is_failure", False):
            raise RuntimeError(f"MQTT connect refused: {reason}")

    def disconnect(self) -> None:
        """Send DISCONNECT and close."""
        with contextlib.suppress(Exception):
            self.client.disconnect()


async def run_mosquitto(
    host: str,
    port: int,
    names: list[str],
    operators: int,
    payloads: Payloads,
    rate: float,
    warmup: float,
    seconds: float,
    qos: int,
    progress: Progress,
    pid: int | None = None,
) -> dict:
    """Publishers and subscribers on Mosquitto with the same load as ours; returns the figures."""
    loop = asyncio.get_running_loop()
    n = len(names)
    pid = pid or mosquitto_pid()
    rec = Recorder(n, operators)
    topics = [f"aerobase/{name}/telemetry" for name in names]
    index = {topic: i for i, topic in enumerate(topics)}
    tag = uuid.uuid4().hex[:6]
    subs = []
    for k in range(operators):
        sub = AsyncMqtt(loop, f"bench-op-{tag}-{k}")

        def on_message(
            _c: mqtt.Client, _u: object, message: mqtt.MQTTMessage, k: int = k, sub: AsyncMqtt = sub
        ) -> None:
            t = time.perf_counter()
            sub.packets += 1
            i = index.get(message.topic)
            if i is not None:
                rec.on_delivered(k, i, json.loads(message.payload)["seq"], t)

        subscribed = loop.create_future()

        def on_subscribe(
            _c: mqtt.Client,
            _u: object,
            _mid: int,
            codes: list,
            _p: object,
            fut: asyncio.Future = subscribed,
        ) -> None:
            if not fut.done():
                fut.set_result(codes)

        sub.client.on_message = on_message
        sub.client.on_subscribe = on_subscribe
        await sub.connect(host, port)
        sub.client.subscribe("aerobase/+/telemetry", qos=0)
        await asyncio.wait_for(subscribed, 30)
        subs.append(sub)
    progress(f"{operators} MQTT subscriber(s) on aerobase/+/telemetry")
    pubs: list[AsyncMqtt] = []
    for i in range(n):
        pub = AsyncMqtt(loop, f"bench-uav-{tag}-{i}")

        def on_publish(
            _c: mqtt.Client,
            _u: object,
            _mid: int,
            _rc: object,
            _p: object,
            i: int = i,
            pub: AsyncMqtt = pub,
        ) -> None:
            pub.packets += 1
            rec.acked[i] += 1  # QoS 1: PUBACK from the broker; QoS 0: written to the socket

        pub.client.on_publish = on_publish
        await pub.connect(host, port)
        pubs.append(pub)
        if (i + 1) % 100 == 0 or i + 1 == n:
            progress(f"connected {i + 1}/{n} MQTT publishers")

    def send(i: int, seq: int) -> None:
        pubs[i].client.publish(topics[i], payloads.text(i, seq), qos=qos)

    try:
        marks = await pace(n, rate, warmup, seconds, rec, send, progress, pid)
        drained = await drain(rec, 15.0)
        marks["end"] = mark(rec, pid)
    finally:
        for client in [*pubs, *subs]:
            client.disconnect()
        await asyncio.sleep(0.2)
    result = figures(rec, marks, drained)
    result["mosquitto_pid"] = pid
    result["mosquitto_set_tcp_nodelay"] = mosquitto_nodelay(pid)
    return result
