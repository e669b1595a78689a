"""The load generator shared by both telemetry benchmark runs: payloads, pacing, recording, figures.

Both runs (ours over WebSockets, Mosquitto over MQTT) send the very same envelope bytes, produced
by `protocol.codec.encode` from `protocol.telemetry_payloads.UavTelemetry`, paced by the same schedule and
measured by the same `Recorder`.
"""

from __future__ import annotations

import asyncio
import math
import os
import random
import time
import uuid
from array import array
from collections.abc import Awaitable, Callable
from dataclasses import dataclass, field

from protocol.codec import decode, encode
from protocol.messages import envelope
from protocol.telemetry_payloads import (
    Attitude,
    Battery,
    Gnss,
    MissionProgress,
    Position,
    UavTelemetry,
    Velocity,
)

_SEQ, _TS = 987_654_321_987, 1_111_111_111_111
_ID = uuid.UUID("0badc0de-0000-4000-8000-00000000beef")
RING = 20  # distinct samples per asset, cycled: a UAV circling its waypoint
_IDS = random.Random()


def message_id() -> str:
    """A fresh random (version 4) UUID without uuid4's system call per id: the generator makes
    10,000 a second at 1,000 UAVs."""
    h = f"{(_IDS.getrandbits(128) & ~(0xF000 << 64) & ~(0xC000 << 48)) | (0x4000 << 64) | (0x8000 << 48):032x}"
    return f"{h[:8]}-{h[8:12]}-{h[12:16]}-{h[16:20]}-{h[20:]}"


def sample(asset: int, k: int) -> UavTelemetry:
    """A realistic UAV sample: asset `asset` at step `k` of a 60 m circle at 20 m above home."""
    angle = 2 * math.pi * (k % RING) / RING + asset
    lat0, lon0 = 41.0 + (asset % 100) * 0.01, -8.6 + (asset // 100) * 0.01
    return UavTelemetry(
        position=Position(
            lat=lat0 + 0.00054 * math.cos(angle),
            lon=lon0 + 0.00072 * math.sin(angle),
            alt_msl_m=140.2 + 0.3 * math.sin(angle),
            alt_rel_m=20.0 + 0.3 * math.sin(angle),
        ),
        velocity=Velocity(
            north_m_s=-6.0 * math.sin(angle), east_m_s=6.0 * math.cos(angle), down_m_s=0.05
        ),
        heading_deg=(math.degrees(angle) + 90) % 360,
        attitude=Attitude(roll_deg=8.5, pitch_deg=-3.2, yaw_deg=(math.degrees(angle) + 90) % 360),
        battery=Battery(percent=88.0 - 0.01 * k, voltage_v=16.1, current_a=12.3),
        gnss=Gnss(fix="rtk_fixed", satellites=21, hdop=0.6),
        flight_mode="AUTO",
        armed=True,
        landed_state="in_air",
        mission=MissionProgress(current=3 + k % 5, total=12),
    )


class Payloads:
    """Pre-encoded envelope templates per asset; `text(i, seq)` fills id, seq and ts."""

    def __init__(self, assets: int) -> None:
        self.templates: list[list[str]] = []
        for i in range(assets):
            ring = []
            for k in range(RING):
                text = encode(envelope(sample(i, k), seq=_SEQ, id=_ID, ts=_TS))
                for token, mark in ((str(_SEQ), "\x00"), (str(_TS), "\x01"), (str(_ID), "\x02")):
                    assert text.count(token) == 1, f"template token {token} is not unique"
                    text = text.replace(token, mark)
                ring.append(text)
            self.templates.append(ring)
        probe = self.text(0, 1)
        assert not hasattr(decode(probe, "asset_to_server"), "code"), "template does not decode"

    def text(self, asset: int, seq: int) -> str:
        """The envelope text of message `seq` of asset `asset` (a fresh id, now as ts)."""
        t = self.templates[asset][seq % RING]
        return (
            t.replace("\x00", str(seq), 1)
            .replace("\x01", str(int(time.time() * 1000)), 1)
            .replace("\x02", message_id(), 1)
        )

    def size(self) -> int:
        """Bytes of one typical message."""
        return len(self.text(0, 12345).encode())


@dataclass
class Recorder:
    """Send times, acks, deliveries and latencies of one run (sender and receivers share it)."""

    assets: int
    operators: int
    window: tuple[float, float] = (math.inf, math.inf)  # perf_counter bounds of the measured window
    sent: list[array] = field(default_factory=list)
    acked: list[int] = field(default_factory=list)
    delivered: list[int] = field(default_factory=list)
    latencies: array = field(default_factory=lambda: array("d"))
    lags: array = field(default_factory=lambda: array("d"))
    errors: int = 0
    duplicates: int = 0
    helper_pids: list[int] = field(default_factory=list)  # generator processes besides this one

    def __post_init__(self) -> None:
        self.sent = [array("d") for _ in range(self.assets)]
        self.acked = [0] * self.assets
        self.delivered = [0] * self.operators

    def on_sent(self, asset: int, t: float, scheduled: float) -> int:
        """Record a send at perf_counter `t`; returns its seq (1, 2, ...)."""
        self.sent[asset].append(t)
        if self.window[0] <= t < self.window[1]:
            self.lags.append(t - scheduled)
        return len(self.sent[asset])

    def on_delivered(self, operator: int, asset: int, seq: int, t: float) -> None:
        """An operator received message `seq` of `asset` at perf_counter `t`."""
        self.delivered[operator] += 1
        sent = self.sent[asset]
        if 0 < seq <= len(sent):
            t0 = sent[seq - 1]
            if self.window[0] <= t0 < self.window[1]:
                self.latencies.append(t - t0)

    def total_sent(self) -> int:
        """Messages sent so far."""
        return sum(len(s) for s in self.sent)

    def settled(self) -> bool:
        """True when every message sent was acked and delivered to every operator."""
        total = self.total_sent()
        return sum(self.acked) >= total and all(d >= total for d in self.delivered)


async def pace(
    n: int,
    rate: float,
    warmup: float,
    seconds: float,
    rec: Recorder,
    send: Callable[[int, int], Awaitable[None] | None],
    progress: Callable[[str], None],
    pid: int | None,
    start: float | None = None,
    phase: tuple[int, int] = (0, 0),
) -> dict:
    """Send from `n` assets at `rate` Hz for warmup + seconds, phases spread evenly; returns marks.

    `send(asset, seq)` sends message `seq` of `asset`. The returned marks are perf_counter times and
    counters at the start and the end of the measured window. Several processes share one schedule
    by passing the same `start` (perf_counter is the system's monotonic clock) and `phase` = (index
    of this process's first asset, assets in all processes).
    """
    period = 1.0 / rate
    start = time.perf_counter() + 0.2 if start is None else start
    first, total = phase if phase[1] else (0, n)
    t_open, t_close = start + warmup, start + warmup + seconds
    rec.window = (t_open, t_close)
    marks: dict = {"start": mark(rec, pid)}

    async def sender() -> None:
        # one loop over the common schedule, not a task and a timer per asset (10,000 wake-ups a
        # second at 1,000 UAVs): what is due within the next millisecond goes out together
        offsets = [period * (first + i) / total for i in range(n)]
        k = 0
        while n and start + k * period < t_close:
            base = start + k * period
            for i in range(n):
                due = base + offsets[i]
                if due >= t_close:
                    return
                delay = due - time.perf_counter()
                if delay > 0.001:
                    await asyncio.sleep(delay)
                elif i % 64 == 63:
                    await asyncio.sleep(0)  # behind schedule: let the readers in now and then
                seq = rec.on_sent(i, time.perf_counter(), due)
                sent = send(i, seq)
                if sent is not None:
                    await sent
            k += 1

    async def marker() -> None:
        await asyncio.sleep(max(0.0, t_open - time.perf_counter()))
        marks["open"] = mark(rec, pid)
        last = time.perf_counter()
        while time.perf_counter() < t_close:
            await asyncio.sleep(min(1.0, max(0.0, t_close - time.perf_counter())))
            if time.perf_counter() - last >= 0.99 or time.perf_counter() >= t_close:
                last = time.perf_counter()
                progress(
                    f"  {last - t_open:4.1f}/{seconds:g} s: sent {rec.total_sent()}, acked {sum(rec.acked)}, "
                    f"delivered {sum(rec.delivered)}"
                )
        marks["close"] = mark(rec, pid)

    await asyncio.gather(marker(), sender())
    return marks


def mark(rec: Recorder, pid: int | None) -> dict:
    """Time, counters and CPU (server, generator, machine) now."""
    return {
        "cpu_server": None if pid is None else process_cpu(pid),
        "t": time.perf_counter(),
        "acked": sum(rec.acked),
        "delivered": sum(rec.delivered),
        "sent": rec.total_sent(),
        "cpu_self": _self_cpu() + sum(process_cpu(p) or 0.0 for p in rec.helper_pids),
        "machine": machine_busy(),
    }


async def drain(rec: Recorder, limit_s: float) -> float:
    """Wait until every message is acked and delivered, or `limit_s` seconds; returns seconds waited."""
    t0 = time.perf_counter()
    while not rec.settled() and time.perf_counter() - t0 < limit_s:  # noqa: ASYNC110 - polls counters
        await asyncio.sleep(0.05)
    return time.perf_counter() - t0


def _self_cpu() -> float:
    t = os.times()
    return t.user + t.system


def process_cpu(pid: int) -> float | None:
    """CPU seconds (user + system) of process `pid`, from /proc/<pid>/stat; None when unreadable."""
    try:
        with open(f"/proc/{pid}/stat") as f:
            fields = f.read().rsplit(")", 1)[1].split()
        return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")
    except (OSError, IndexError, ValueError):
        return None


def machine_busy() -> tuple[int, int]:
    """(busy, total) jiffies of the whole machine, from /proc/stat."""
    try:
        with open("/proc/stat") as f:
            values = [int(v) for v in f.readline().split()[1:]]
        idle = values[3] + (values[4] if len(values) > 4 else 0)
        return sum(values) - idle, sum(values)
    except (OSError, ValueError):
        return 0, 0


def _other_cpu(o: dict, c: dict, server_cpu: float | None) -> float | None:
    """CPU seconds the rest of the machine (other processes, kernel softirq) used in the window."""
    if server_cpu is None:
        return None
    busy_s = (c["machine"][0] - o["machine"][0]) / os.sysconf("SC_CLK_TCK")
    return round(max(0.0, busy_s - server_cpu - (c["cpu_self"] - o["cpu_self"])), 2)


def percentile(values: array | list[float], q: float) -> float | None:
    """The q-th percentile (nearest rank) of `values`, None when empty."""
    if not values:
        return None
    ordered = sorted(values)
    rank = max(1, math.ceil(q / 100 * len(ordered)))
    return ordered[rank - 1]


def figures(rec: Recorder, marks: dict, drained_s: float) -> dict:
    """The figures of one run, in ms, messages/s and CPU seconds per 1,000 messages.

    `marks` holds `start` (before the first send), `open` and `close` (the measured window) and
    `end` (after the drain).
    """
    o, c = marks["open"], marks["close"]
    s0, e = marks["start"], marks["end"]
    run_cpu = (
        None
        if s0["cpu_server"] is None or e["cpu_server"] is None
        else e["cpu_server"] - s0["cpu_server"]
    )
    acked_window = c["acked"] - o["acked"]
    delivered_window = c["delivered"] - o["delivered"]
    window_s = c["t"] - o["t"]
    total = rec.total_sent()
    cpu0, cpu1 = o["cpu_server"], c["cpu_server"]
    cpu = None if cpu0 is None or cpu1 is None else cpu1 - cpu0
    busy = (c["machine"][0] - o["machine"][0]) / max(1, c["machine"][1] - o["machine"][1])
    lat = rec.latencies

    def ms(q: float) -> float | None:
        v = percentile(lat, q)
        return None if v is None else round(v * 1000, 3)

    return {
        "sent": total,
        "acked": sum(rec.acked),
        "delivered": sum(rec.delivered),
        "offered_rate_msg_s": round((c["sent"] - o["sent"]) / window_s, 1),
        "ingest_rate_msg_s": round(acked_window / window_s, 1),
        "delivered_rate_msg_s": round(delivered_window / window_s, 1),
        "latency_ms": {
            "p50": ms(50),
            "p95": ms(95),
            "p99": ms(99),
            "max": None if not lat else round(max(lat) * 1000, 3),
            "samples": len(lat),
        },
        "cpu_s_per_1000": None
        if cpu is None or acked_window <= 0
        else round(cpu / acked_window * 1000, 4),
        "cpu_s": None if cpu is None else round(cpu, 2),
        "cpu_s_per_1000_whole_run": None
        if run_cpu is None or e["acked"] <= 0
        else round(run_cpu / e["acked"] * 1000, 4),
        "lost_ingest": total - sum(rec.acked),
        "lost_delivery": total * rec.operators - sum(rec.delivered),
        "errors": rec.errors,
        "generator_cpu_s": round(c["cpu_self"] - o["cpu_self"], 2),
        "generator_send_lag_ms_p99": None
        if not rec.lags
        else round(percentile(rec.lags, 99) * 1000, 3),
        "machine_busy_pct": round(100 * busy, 1),
        "other_processes_cpu_s": _other_cpu(o, c, cpu),
        "window_s": round(window_s, 2),
        "drain_s": round(drained_s, 2),
    }
