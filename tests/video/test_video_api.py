"""Live video over the embedded relay: a WHIP publisher, in-process WHEP viewers, access rules."""

from __future__ import annotations

import base64
import hashlib
import hmac
import time
from typing import Any

import httpx
import pytest

from tests.conftest import LiveServer, Tenant, auth
from tests.metrics import value
from tests.polling import eventually
from tests.server.realtime_client import next_of, operator_socket
from tests.video.conftest import MAX_VIEWERS, TURN_SECRET
from tests.video.peers import Viewer, publisher

CAMERA = {"width": 320, "height": 240, "fps": 20}


def uav_with_camera(
    tenant: Tenant, api: httpx.Client, camera: dict[str, Any] | bool | None = None
) -> tuple[str, str]:
    """A UAV with a camera description (CAMERA by default; False: described as having none), and
    its asset session token."""
    from assetlink.configfile import decrypt_config

    asset = tenant.create_asset(
        "uav",
        password="asset-password-123",
        attributes={"camera": CAMERA if camera is None else camera},
    )
    cfg = decrypt_config(base64.b64decode(asset["config_file"]), "asset-password-123")
    r = api.post("/api/v1/assets/login", json={"name": cfg.name, "secret": cfg.secret})
    assert r.status_code == 200, r.text
    return asset["id"], r.json()["access_token"]


def test_the_description_carries_the_camera_and_coturn_rest_credentials(
    video_api: httpx.Client, video_tenant: Tenant
):
    asset_id, _ = uav_with_camera(video_tenant, video_api)
    before = int(time.time())
    r = video_api.get(f"/api/v1/assets/{asset_id}/video", headers=video_tenant.h("viewer"))
    assert r.status_code == 200, r.text
    body = r.json()
    assert body["state"] == "offline" and body["path"] == "embedded" and body["codec"] == "vp8"
    assert (body["width"], body["height"], body["fps"]) == (320, 240, 20)
    assert body["viewers"] == 0 and body["max_viewers"] == MAX_VIEWERS
    assert body["whep_url"] == f"/api/v1/assets/{asset_id}/video/whep"
    stun, turn = body["ice_servers"]
    assert stun == {"urls": ["stun:127.0.0.1:3478"], "username": None, "credential": None}
    expiry, user = turn["username"].split(":")
    assert user == video_tenant.user_ids["viewer"]
    assert before + 3600 <= int(expiry) <= int(time.time()) + 3600
    expected = hmac.new(TURN_SECRET.encode(), turn["username"].encode(), hashlib.sha1).digest()
    assert turn["credential"] == base64.b64encode(expected).decode()


def test_no_token_is_401_and_another_organisation_is_404(
    video_api: httpx.Client, video_tenant: Tenant, superuser_email: str
):
    asset_id, _ = uav_with_camera(video_tenant, video_api)
    other = Tenant(video_api, superuser_email, label="video-other")
    sdp = {"Content-Type": "application/sdp"}
    assert video_api.get(f"/api/v1/assets/{asset_id}/video").status_code == 401
    r = video_api.post(f"/api/v1/assets/{asset_id}/video/whep", content="v=0\r\n", headers=sdp)
    assert r.status_code == 401
    r = video_api.get(f"/api/v1/assets/{asset_id}/video", headers=other.h("viewer"))
    assert r.status_code == 404
    r = video_api.post(
        f"/api/v1/assets/{asset_id}/video/whep",
        content="v=0\r\n",
        headers={**sdp, **other.h("admin")},
    )
    assert r.status_code == 404
    # a user cannot publish as the asset; another asset cannot either
    r = video_api.post(
        f"/api/v1/assets/{asset_id}/video/whip",
        content="v=0\r\n",
        headers={**sdp, **video_tenant.h()},
    )
    assert r.status_code == 403
    _, other_asset_token = uav_with_camera(other, video_api)
    r = video_api.post(
        f"/api/v1/assets/{asset_id}/video/whip",
        content="v=0\r\n",
        headers={**sdp, **auth(other_asset_token)},
    )
    assert r.status_code == 404


def test_bad_offers_are_clear_errors(video_api: httpx.Client, video_tenant: Tenant):
    asset_id, _ = uav_with_camera(video_tenant, video_api)
    url = f"/api/v1/assets/{asset_id}/video/whep"
    h = video_tenant.h("viewer")
    r = video_api.post(url, json={"sdp": "v=0"}, headers=h)
    assert r.status_code == 415 and r.json()["error"]["code"] == "unsupported_media_type"
    r = video_api.post(url, content="hello", headers={**h, "Content-Type": "application/sdp"})
    assert r.status_code == 422 and r.json()["error"]["code"] == "bad_offer"
    r = video_api.post(
        url, content=b"v=0\r\nm=garbage", headers={**h, "Content-Type": "application/sdp"}
    )
    assert r.status_code in (400, 422), r.text
    gone = f"{url}/00000000-0000-0000-0000-000000000000"
    assert video_api.delete(gone, headers=h).status_code == 404


def test_a_uav_described_without_a_camera_has_no_stream_until_it_is_given_one(
    video_api: httpx.Client, video_tenant: Tenant
):
    """`attributes.camera: false`: every way to a stream answers 404 no_camera (not a default
    camera's offline stream); its recordings still list; a camera described later is streamed."""
    asset_id, token = uav_with_camera(video_tenant, video_api, camera=False)
    own = auth(token)
    url, sdp = f"/api/v1/assets/{asset_id}/video", {"Content-Type": "application/sdp"}
    viewer = video_tenant.h("viewer")
    answers = {
        "description": video_api.get(url, headers=viewer),
        "WHEP offer": video_api.post(f"{url}/whep", content="v=0\r\n", headers={**sdp, **viewer}),
        "WHIP offer": video_api.post(f"{url}/whip", content="v=0\r\n", headers={**sdp, **own}),
        "RTP target": video_api.post(f"{url}/rtp", headers=own),
    }
    for what, r in answers.items():
        assert r.status_code == 404, (what, r.status_code, r.text)
        assert r.json()["error"]["code"] == "no_camera", (what, r.text)
        assert "attributes.camera is false" in r.json()["error"]["message"], (what, r.text)
    r = video_api.get(f"{url}/recordings", headers=viewer)
    assert r.status_code == 200 and r.json() == [], r.text

    r = video_api.patch(
        f"/api/v1/assets/{asset_id}",
        json={"attributes": {"camera": CAMERA}},
        headers=video_tenant.h(),
    )
    assert r.status_code == 200, r.text
    r = video_api.get(url, headers=viewer)
    assert r.status_code == 200, r.text
    assert (r.json()["width"], r.json()["height"], r.json()["state"]) == (320, 240, "offline")


@pytest.mark.slow
async def test_viewers_get_frames_of_the_camera_size_and_the_limit_answers_503(
    video_server: LiveServer, video_api: httpx.Client, video_tenant: Tenant
):
    asset_id, asset_token = uav_with_camera(video_tenant, video_api)
    pub = publisher(video_server.url, asset_id, asset_token, 320, 240, 20)
    await pub.publish_once()
    viewers = [
        Viewer(video_server.url, asset_id, video_tenant.tokens["viewer"])
        for _ in range(MAX_VIEWERS)
    ]
    try:
        for v in viewers:
            r = await v.offer()
            assert r.status_code == 201, r.text
            assert r.headers["content-type"].startswith("application/sdp")
            assert r.headers["location"].startswith(f"/api/v1/assets/{asset_id}/video/whep/")
        await eventually(
            lambda: all(v.frames >= 30 for v in viewers), within=30, what="30 frames per viewer"
        )
        assert all(v.sizes == {(320, 240)} for v in viewers), [v.sizes for v in viewers]
        extra = Viewer(video_server.url, asset_id, video_tenant.tokens["operator"])
        r = await extra.offer()
        assert r.status_code == 503 and r.headers["retry-after"] == "7"
        assert r.json()["error"]["code"] == "viewer_limit"
        async with httpx.AsyncClient(base_url=video_server.url) as c:
            r = await c.get(f"/api/v1/assets/{asset_id}/video", headers=video_tenant.h("viewer"))
        body = r.json()
        assert body["state"] == "live" and body["viewers"] == MAX_VIEWERS
        async with httpx.AsyncClient(base_url=video_server.url) as c:
            metrics = (await c.get("/metrics")).text
        # one registry per process: other test servers' relays may add to these
        assert value(metrics, "aerobase_video_viewers") >= MAX_VIEWERS
        assert value(metrics, "aerobase_video_publishers") >= 1
        assert value(metrics, "aerobase_video_frames_forwarded_total") >= 30 * MAX_VIEWERS
        assert body["measured_fps"] is not None and body["measured_fps"] > 5
        # a viewer that leaves frees its place
        await viewers[0].close()
        assert (await extra.offer()).status_code == 201
        viewers[0] = extra
        await eventually(lambda: extra.frames >= 10, within=20, what="frames for the new viewer")
    finally:
        for v in viewers:
            await v.close()
        await pub.stop()
        await pub.track.aclose()  # type: ignore[attr-defined]


@pytest.mark.slow
async def test_operators_following_a_uav_are_told_when_its_video_goes_live_and_offline(
    video_server: LiveServer, video_api: httpx.Client, video_tenant: Tenant
):
    asset_id, asset_token = uav_with_camera(video_tenant, video_api)
    async with operator_socket(video_server.url, video_tenant.tokens["viewer"], (asset_id,)) as ws:
        pub = publisher(video_server.url, asset_id, asset_token, 320, 240, 20)
        try:
            await pub.publish_once()
            live = (await next_of(ws, "video_state", within=10))["payload"]
            assert live == {"asset_id": asset_id, "state": "live"}
            # what the description says at that moment, too
            async with httpx.AsyncClient(base_url=video_server.url) as c:
                desc = await c.get(
                    f"/api/v1/assets/{asset_id}/video", headers=video_tenant.h("viewer")
                )
            assert desc.json()["state"] == "live"
            await pub.stop()  # the UAV ends its publication (WHIP DELETE)
            assert (await next_of(ws, "video_state", within=10))["payload"] == {
                "asset_id": asset_id,
                "state": "offline",
            }
        finally:
            await pub.stop()
            await pub.track.aclose()  # type: ignore[attr-defined]
