"""A server with live video for the video tests (loopback ICE allowed: see server/video/ice.py)."""

from __future__ import annotations

from collections.abc import Iterator

import httpx
import pytest

from tests.conftest import LiveServer, Tenant, test_settings

TURN_SECRET = "video-test-turn-secret"
MAX_VIEWERS = 3


@pytest.fixture(scope="module")
def video_server(database_url: str) -> Iterator[LiveServer]:
    """A server whose relay offers loopback candidates only, with a small viewer limit."""
    server = LiveServer(
        test_settings(
            database_url,
            video_ice_loopback=True,
            video_max_viewers=MAX_VIEWERS,
            video_retry_after_s=7,
            video_stun_urls=["stun:127.0.0.1:3478"],
            video_turn_urls=["turn:127.0.0.1:3478?transport=udp"],
            video_turn_secret=TURN_SECRET,
        )
    ).start()
    yield server
    server.stop()


@pytest.fixture(scope="module")
def video_api(video_server: LiveServer) -> Iterator[httpx.Client]:
    """An HTTP client for the video server."""
    with httpx.Client(base_url=video_server.url, timeout=30) as client:
        yield client


@pytest.fixture
def video_tenant(video_api: httpx.Client, superuser_email: str) -> Tenant:
    """A fresh organisation on the video server."""
    return Tenant(video_api, superuser_email, label="video")
