"""A session's end stops what it holds in the media path, as it closes its sockets: the viewers a
user's session opened (logout, a disabled account) and the publication an asset's session opened
(a configuration reissued) or that expired. Over real HTTP with in-process aiortc peers (tests/video/peers.py)."""

from __future__ import annotations

import time
from collections.abc import Iterator

import httpx
import pytest

from tests.conftest import LiveServer, Tenant, test_settings
from tests.polling import eventually
from tests.video.peers import Viewer, publisher
from tests.video.test_video_api import uav_with_camera

ENDS_WITHIN_S = 1.0  # the bound the operator sockets keep (tests/server/test_session_end.py)


def _ended(viewer: Viewer) -> bool:
    assert viewer.pc is not None
    return viewer.pc.connectionState in ("closed", "failed")


async def _viewers(server: LiveServer, tenant: Tenant, asset_id: str) -> int:
    async with httpx.AsyncClient(base_url=server.url, timeout=15) as c:
        r = await c.get(f"/api/v1/assets/{asset_id}/video", headers=tenant.h("admin"))
    assert r.status_code == 200, r.text
    return int(r.json()["viewers"])


@pytest.mark.slow
async def test_logout_and_disabling_end_that_sessions_viewers_within_a_second(
    video_server: LiveServer, video_api: httpx.Client, video_tenant: Tenant
):
    asset_id, asset_token = uav_with_camera(video_tenant, video_api)
    pub = publisher(video_server.url, asset_id, asset_token, 320, 240, 20)
    await pub.publish_once()
    watching = Viewer(video_server.url, asset_id, video_tenant.tokens["viewer"])
    operator = Viewer(video_server.url, asset_id, video_tenant.tokens["operator"])
    admin = Viewer(video_server.url, asset_id, video_tenant.tokens["admin"])
    viewers = [watching, operator, admin]
    try:
        for v in viewers:
            assert (await v.offer()).status_code == 201
        await eventually(
            lambda: all(v.frames >= 10 for v in viewers), within=30, what="frames for each viewer"
        )
        assert await _viewers(video_server, video_tenant, asset_id) == 3

        # logout: the viewer's own session ends
        async with httpx.AsyncClient(base_url=video_server.url, timeout=15) as c:
            started = time.monotonic()
            r = await c.post("/api/v1/auth/logout", headers=video_tenant.h("viewer"))
        assert r.status_code == 204, r.text
        await eventually(lambda: _ended(watching), within=10, what="the logged-out viewer's end")
        assert time.monotonic() - started <= ENDS_WITHIN_S + 0.5, time.monotonic() - started
        assert await _viewers(video_server, video_tenant, asset_id) == 2

        # an admin disables the operator: every session of theirs ends, their viewer with it
        async with httpx.AsyncClient(base_url=video_server.url, timeout=15) as c:
            started = time.monotonic()
            r = await c.patch(
                f"/api/v1/users/{video_tenant.user_ids['operator']}",
                headers=video_tenant.h("admin"),
                json={"is_active": False},
            )
        assert r.status_code == 200, r.text
        await eventually(lambda: _ended(operator), within=10, what="the disabled user's viewer end")
        assert time.monotonic() - started <= ENDS_WITHIN_S + 0.5, time.monotonic() - started
        assert await _viewers(video_server, video_tenant, asset_id) == 1

        # the admin's viewer, whose session lives on, still gets frames
        before = admin.frames
        await eventually(lambda: admin.frames >= before + 10, within=10, what="admin's frames")
        assert not _ended(admin)
    finally:
        for v in viewers:
            await v.close()
        await pub.stop()
        await pub.track.aclose()  # type: ignore[attr-defined]


@pytest.mark.slow
async def test_a_config_reissue_ends_the_assets_publication(
    video_server: LiveServer, video_api: httpx.Client, video_tenant: Tenant
):
    asset_id, asset_token = uav_with_camera(video_tenant, video_api)
    pub = publisher(video_server.url, asset_id, asset_token, 320, 240, 20)
    ended = await pub.publish_once()
    try:

        async def live() -> bool:
            async with httpx.AsyncClient(base_url=video_server.url, timeout=15) as c:
                r = await c.get(f"/api/v1/assets/{asset_id}/video", headers=video_tenant.h())
            return r.json()["state"] == "live"

        await eventually(live, within=30, what="the stream live")
        async with httpx.AsyncClient(base_url=video_server.url, timeout=15) as c:
            started = time.monotonic()
            r = await c.post(
                f"/api/v1/assets/{asset_id}/config",
                headers=video_tenant.h("admin"),
                json={"password": "another-password-1"},
            )
        assert r.status_code == 200, r.text
        await eventually(ended.is_set, within=10, what="the publisher's connection to end")
        assert time.monotonic() - started <= ENDS_WITHIN_S + 0.5, time.monotonic() - started
        await eventually(
            lambda: _not(live()), within=10, what="the stream offline after the session ended"
        )
    finally:
        await pub.stop()
        await pub.track.aclose()  # type: ignore[attr-defined]


async def _not(value) -> bool:  # type: ignore[no-untyped-def]
    return not await value


@pytest.fixture
def short_ttl_server(database_url: str) -> Iterator[LiveServer]:
    """A video server whose sessions reach their TTL after TTL_S (assigned after validation,
    below what the settings accept from the environment, for this test only)."""
    settings = test_settings(database_url, video_ice_loopback=True)
    settings.session_ttl_s = TTL_S
    server = LiveServer(settings).start()
    yield server
    server.stop()


TTL_S = 6


@pytest.mark.slow
async def test_a_viewer_ends_when_its_session_expires(
    short_ttl_server: LiveServer, superuser_email: str
):
    server = short_ttl_server
    with httpx.Client(base_url=server.url, timeout=30) as api:
        tenant = Tenant(api, superuser_email, label="video-ttl")
        asset_id, asset_token = uav_with_camera(tenant, api)
    body = {"email": tenant.emails["viewer"], "password": Tenant.PASSWORD, "force": True}
    async with httpx.AsyncClient(base_url=server.url, timeout=30) as c:
        logged_in = time.monotonic()
        r = await c.post("/api/v1/auth/login", json=body)
    assert r.status_code == 200, r.text
    viewer = Viewer(server.url, asset_id, r.json()["access_token"])
    pub = publisher(server.url, asset_id, asset_token, 320, 240, 20)
    try:
        await pub.publish_once()
        assert (await viewer.offer()).status_code == 201
        await eventually(lambda: viewer.frames >= 5, within=TTL_S, what="frames before expiry")
        # no request after the offer: the session dies at login + TTL_S, the viewer with it
        await eventually(lambda: _ended(viewer), within=TTL_S + 5, what="the expired viewer's end")
        ended = time.monotonic() - logged_in
        assert TTL_S - 0.1 <= ended <= TTL_S + ENDS_WITHIN_S + 0.5, ended
    finally:
        await viewer.close()
        await pub.stop()
        await pub.track.aclose()  # type: ignore[attr-defined]
