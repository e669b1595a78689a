"""Link parts that need no server: backoff, URLs, token timing, offline queueing across restarts.

End-to-end behaviour against the real `/ws/asset` is tested with the server (tests/e2e).
"""

from __future__ import annotations

import random
import socket
from pathlib import Path

import pytest

from assetlink.auth import parse_expiry
from assetlink.link import Link, backoff_delay, renew_at, ws_url
from assetlink.outbox import Outbox, Token
from assetlink.settings import LinkSettings
from asynckit.ratelimit import TokenBucket
from protocol import rtcm
from protocol import telemetry_payloads as t
from protocol.messages import EventPayload


def closed_port_url() -> str:
    """An http URL on 127.0.0.1 where nothing listens (the OS gave the port, then it closed)."""
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        port = sock.getsockname()[1]
    return f"http://127.0.0.1:{port}"


def test_backoff_grows_exponentially_with_full_jitter() -> None:
    rng = random.Random(7)
    for attempt in range(12):
        cap = min(30.0, 0.5 * 2**attempt)
        samples = [backoff_delay(attempt, 0.5, 30.0, rng) for _ in range(200)]
        assert all(0 <= s <= cap for s in samples)
        assert max(samples) > cap * 0.8  # full jitter spreads over the whole range
    assert backoff_delay(10_000, 0.5, 30.0, rng) <= 30.0


def test_ws_url_from_server_url() -> None:
    assert ws_url("http://127.0.0.1:8000") == "ws://127.0.0.1:8000/ws/asset"
    assert ws_url("https://aero.example/base/") == "wss://aero.example/base/ws/asset"


def test_renew_after_three_quarters_of_the_remaining_life() -> None:
    token = Token("x", expires_at=1000.0)
    assert renew_at(token, now=600.0) == 900.0
    assert renew_at(token, now=2000.0) == 2000.0


def test_parse_expiry_accepts_offsets_z_and_naive_utc() -> None:
    assert parse_expiry("2026-01-01T00:00:00Z") == 1767225600.0
    assert parse_expiry("2026-01-01T01:00:00+01:00") == 1767225600.0
    assert parse_expiry("2026-01-01T00:00:00") == 1767225600.0


async def test_offline_link_queues_durably_and_keeps_its_stream(tmp_path: Path) -> None:
    state = tmp_path / "state" / "link.sqlite"
    url = closed_port_url()
    link = Link(
        url,
        "uav-1",
        "secret",
        state,
        LinkSettings(max_outbox=5, backoff_min=0.01, backoff_max=0.05),
    )
    with pytest.raises(RuntimeError):
        await link.send_event(EventPayload(name="too_early"))
    await link.start()
    stream = link.stream_id
    for i in range(7):
        await link.send_telemetry(t.UavTelemetry(mission=t.MissionProgress(current=i, total=7)))
    await link.send_event(EventPayload(name="boot", message="started"))
    assert not link.connected
    assert not await link.send_rtcm(rtcm.build_frame(b"\x3e\xd0"))
    assert not await link.flush(0.05)
    stats = link.stats
    assert stats.queued == 5 and stats.dropped == 3 and stats.rtcm_dropped == 1
    assert stats.sent == 0
    with pytest.raises(TypeError):
        await link.send_telemetry({"kind": "uav"})  # type: ignore[arg-type]
    with pytest.raises(ValueError):
        await link.send_event(EventPayload(name="big", data={"blob": "x" * 2_000_000}))
    await link.stop()

    again = Link(url, "uav-1", "secret", state, LinkSettings(max_outbox=5))
    await again.start()
    assert again.stream_id == stream and again.stats.queued == 5
    await again.stop()
    box = Outbox(state)
    assert box.dropped_unreported() == 3
    assert [e.type for e in box.take(10)] == ["telemetry"] * 4 + ["event"]


async def test_what_a_daemon_remembers_outlives_it_apart_from_the_links_own_keys(
    tmp_path: Path,
) -> None:
    """`remember` is committed when it returns: the next daemon on the state file recalls it."""
    state, url = tmp_path / "link.sqlite", closed_port_url()
    link = Link(url, "uav-1", "secret", state)
    await link.start()
    assert await link.recall("precland.takeover") is None
    await link.remember("precland.takeover", "flying")
    await link.remember("identity", "not the link's")  # a daemon's key never overwrites the link's
    await link.stop()

    again = Link(url, "uav-1", "secret", state)
    await again.start()
    assert await again.recall("precland.takeover") == "flying"
    assert await again.recall("identity") == "not the link's"
    assert Outbox(state).meta("identity") == f"{url}|uav-1"
    await again.remember("precland.takeover", None)
    assert await again.recall("precland.takeover") is None
    await again.stop()


def test_link_pacing_stays_under_the_servers_default_limit() -> None:
    """Over any span t, the link sends at most burst + rate*t, the server accepts 400 + 200*t."""
    link = Link("http://127.0.0.1:1", "uav-1", "secret", "unused.sqlite")
    assert link.settings.traffic.burst <= 400 and link.settings.traffic.max_rate <= 200
    with pytest.raises(ValueError):
        TokenBucket(rate=0, burst=10)
