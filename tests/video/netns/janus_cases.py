"""The Janus media path against Debian's Janus, run by test_video_janus.py in a private network.

Not collected on its own (not named test_*): outside that namespace Janus has no interface to use.
"""

from __future__ import annotations

import asyncio
import contextlib
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import httpx
import pytest
from aiortc import RTCConfiguration, RTCPeerConnection, RTCSessionDescription
from aiortc.mediastreams import MediaStreamError

from aerobase.ports import free_port
from asset_agent.video.rtp import RtpPublisher
from asset_agent.video.source import CameraTrack
from server.realtime import hub as realtime_hub
from tests.conftest import LiveServer, Tenant, auth, test_settings
from tests.polling import eventually
from tests.server.realtime_client import next_of, operator_socket
from tests.video.netns.janus_env import RTP_PORTS, Janus, in_private_network
from tests.video.peers import pattern
from tests.video.test_video_api import uav_with_camera


@pytest.fixture(scope="module")
def janus(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Janus]:
    assert in_private_network(), "run these cases through tests/video/test_video_janus.py"
    j = Janus(tmp_path_factory.mktemp("janus"), free_port()).start()
    yield j
    j.stop()


@pytest.fixture(scope="module")
def server(database_url: str, janus: Janus) -> Iterator[LiveServer]:
    s = LiveServer(
        test_settings(database_url, janus_url=janus.url, janus_rtp_host="127.0.0.1")
    ).start()
    yield s
    s.stop()


@pytest.fixture
def tenant(server: LiveServer, superuser_email: str) -> Iterator[Tenant]:
    with httpx.Client(base_url=server.url, timeout=30) as api:
        yield Tenant(api, superuser_email, label="janus")


class JanusViewer:
    """An aiortc viewer on the Janus path: POST empty, answer Janus's offer with PATCH."""

    def __init__(self, url: str, asset_id: str, token: str) -> None:
        self.url, self.asset_id, self.token = url, asset_id, token
        self.frames = 0
        self.sizes: set[tuple[int, int]] = set()
        self.pc = RTCPeerConnection(RTCConfiguration(iceServers=[]))
        self.tasks: list[asyncio.Task[None]] = []
        self.location: str | None = None

    async def start(self) -> httpx.Response:
        h = {"Authorization": f"Bearer {self.token}", "Content-Type": "application/sdp"}
        self.pc.on("track", lambda t: self.tasks.append(asyncio.ensure_future(self._read(t))))
        async with httpx.AsyncClient(base_url=self.url, timeout=30) as c:
            r = await c.post(f"/api/v1/assets/{self.asset_id}/video/whep", content=b"", headers=h)
            if r.status_code != 201:
                return r
            self.location = r.headers["location"]
            await self.pc.setRemoteDescription(RTCSessionDescription(sdp=r.text, type="offer"))
            await self.pc.setLocalDescription(await self.pc.createAnswer())
            answered = await c.patch(self.location, content=self.pc.localDescription.sdp, headers=h)
            assert answered.status_code == 204, answered.text
        return r

    async def _read(self, track: Any) -> None:
        with contextlib.suppress(MediaStreamError):
            while True:
                frame = await track.recv()
                self.frames += 1
                self.sizes.add((frame.width, frame.height))

    async def close(self) -> None:
        if self.location:
            async with httpx.AsyncClient(base_url=self.url, timeout=30) as c:
                await c.delete(self.location, headers=auth(self.token))
        await self.pc.close()
        for t in self.tasks:
            t.cancel()


def rtp_publisher(server: LiveServer, asset_id: str, token: str) -> RtpPublisher:
    track = CameraTrack(pattern(320, 240), 320, 240, 20)
    return RtpPublisher(server.url, asset_id, lambda: token, track, recheck_s=2.0)


async def test_the_asset_asks_where_to_stream_and_janus_chooses_the_port(
    server: LiveServer, tenant: Tenant
):
    asset_id, token = uav_with_camera(tenant, httpx.Client(base_url=server.url))
    async with httpx.AsyncClient(base_url=server.url, timeout=30) as c:
        r = await c.post(f"/api/v1/assets/{asset_id}/video/rtp", headers=auth(token))
        assert r.status_code == 200, r.text
        target = r.json()
        assert RTP_PORTS[0] <= target["port"] <= RTP_PORTS[1]
        assert (target["host"], target["payload_type"], target["codec"]) == ("127.0.0.1", 96, "vp8")
        assert (target["width"], target["height"], target["fps"]) == (320, 240, 20)
        again = await c.post(f"/api/v1/assets/{asset_id}/video/rtp", headers=auth(token))
        assert again.json()["port"] == target["port"]  # one mountpoint per asset
        # WHIP is refused with where to go instead; a user cannot ask for the RTP target
        whip = await c.post(
            f"/api/v1/assets/{asset_id}/video/whip",
            content="v=0\r\n",
            headers={**auth(token), "Content-Type": "application/sdp"},
        )
        assert whip.status_code == 409 and whip.json()["error"]["code"] == "use_rtp"
        user = await c.post(f"/api/v1/assets/{asset_id}/video/rtp", headers=tenant.h("admin"))
        assert user.status_code == 403
        desc = (await c.get(f"/api/v1/assets/{asset_id}/video", headers=tenant.h("viewer"))).json()
        assert desc["path"] == "janus" and desc["viewer_offers"] is False
        assert desc["state"] == "offline"


@pytest.mark.slow
async def test_a_viewer_gets_frames_through_janus(server: LiveServer, tenant: Tenant):
    asset_id, token = uav_with_camera(tenant, httpx.Client(base_url=server.url))
    pub = rtp_publisher(server, asset_id, token)
    sending = asyncio.create_task(pub.run())
    viewer = JanusViewer(server.url, asset_id, tenant.tokens["viewer"])
    try:
        await eventually(lambda: pub.packets > 50, within=20, what="RTP sent to Janus")
        r = await viewer.start()
        assert r.status_code == 201, r.text
        assert "VP8/90000" in r.text  # Janus's offer, from the mountpoint's camera description
        await eventually(lambda: viewer.frames >= 30, within=30, what="30 frames through Janus")
        assert viewer.sizes == {(320, 240)}
        async with httpx.AsyncClient(base_url=server.url, timeout=30) as c:
            desc = await c.get(f"/api/v1/assets/{asset_id}/video", headers=tenant.h("viewer"))
            assert desc.json()["state"] == "live" and desc.json()["viewers"] == 1

            # the viewer vanishes without a DELETE: Janus hangs up and the server reaps it
            await viewer.pc.close()

            async def reaped() -> bool:
                r = await c.get(f"/api/v1/assets/{asset_id}/video", headers=tenant.h("viewer"))
                return r.json()["viewers"] == 0

            await eventually(reaped, within=40, what="the vanished viewer reaped", interval=0.5)
            stale = await c.delete(str(viewer.location), headers=tenant.h("viewer"))
            assert stale.status_code == 404  # its session is gone from the server too
            viewer.location = None
    finally:
        await viewer.close()
        sending.cancel()
        await pub.track.aclose()


@pytest.mark.slow
async def test_operators_following_the_uav_are_told_once_its_rtp_reaches_janus(
    server: LiveServer, tenant: Tenant
):
    """`live` once, when the media arrives: not when the UAV asks where to send it, not again
    when it asks a second time before sending, nor at each re-ask while it streams."""
    asset_id, token = uav_with_camera(tenant, httpx.Client(base_url=server.url))
    rtp = f"/api/v1/assets/{asset_id}/video/rtp"
    async with (
        operator_socket(server.url, tenant.tokens["viewer"], (asset_id,)) as ws,
        httpx.AsyncClient(base_url=server.url, timeout=30) as c,
    ):
        # asked, no media yet: nothing is said (a server that announced at the ask would have
        # within milliseconds; this one is looking every POLL_S for the media meanwhile)
        assert (await c.post(rtp, headers=auth(token))).status_code == 200
        with pytest.raises(TimeoutError):
            await next_of(ws, "video_state", within=3)
        pub = rtp_publisher(server, asset_id, token)  # it asks again, then sends
        sending = asyncio.create_task(pub.run())
        try:
            assert (await next_of(ws, "video_state", within=25))["payload"] == {
                "asset_id": asset_id,
                "state": "live",
            }
            assert pub.packets > 0
            desc = await c.get(f"/api/v1/assets/{asset_id}/video", headers=tenant.h("viewer"))
            assert desc.json()["state"] == "live"
            # streaming, it asks again (as the agent does every few seconds): nothing new to say
            for _ in range(2):
                assert (await c.post(rtp, headers=auth(token))).status_code == 200
            with pytest.raises(TimeoutError):
                await next_of(ws, "video_state", within=3)
        finally:
            sending.cancel()
            await pub.track.aclose()


@pytest.mark.slow
async def test_logging_out_hangs_up_that_sessions_janus_viewer(
    server: LiveServer, tenant: Tenant, monkeypatch: pytest.MonkeyPatch
):
    # the hub reads every session again at least each RECHECK_S (30 s), which would detach the
    # viewer too: made an hour here, only the logout's announcement detaches it within the wait
    monkeypatch.setattr(realtime_hub, "RECHECK_S", 3600.0)
    asset_id, token = uav_with_camera(tenant, httpx.Client(base_url=server.url))
    pub = rtp_publisher(server, asset_id, token)
    sending = asyncio.create_task(pub.run())
    viewer = JanusViewer(server.url, asset_id, tenant.tokens["viewer"])
    try:
        await eventually(lambda: pub.packets > 50, within=20, what="RTP sent to Janus")
        assert (await viewer.start()).status_code == 201
        await eventually(lambda: viewer.frames >= 10, within=30, what="frames through Janus")
        async with httpx.AsyncClient(base_url=server.url, timeout=30) as c:

            async def viewers() -> int:
                r = await c.get(f"/api/v1/assets/{asset_id}/video", headers=tenant.h("admin"))
                return int(r.json()["viewers"])

            assert await viewers() == 1
            r = await c.post("/api/v1/auth/logout", headers=tenant.h("viewer"))
            assert r.status_code == 204, r.text

            async def detached() -> bool:
                return await viewers() == 0

            # the handle is detached: Janus counts the viewer gone and hangs up its peer
            await eventually(detached, within=10, what="the logged-out viewer's handle detached")
            await eventually(
                lambda: viewer.pc.connectionState in ("closed", "failed"),
                within=10,
                what="Janus hanging up the viewer's peer",
            )
            gone = await c.delete(str(viewer.location), headers=tenant.h("admin"))
            assert gone.status_code == 404  # the server forgot the session too
            viewer.location = None
    finally:
        await viewer.close()
        sending.cancel()
        await pub.track.aclose()


def test_readiness_names_janus_when_it_does_not_answer(server: LiveServer, janus: Janus):
    """/api/ready checks Janus on the Janus path: 503 naming it while it is down, 200 again after."""
    with httpx.Client(base_url=server.url, timeout=10) as api:
        up = api.get("/api/ready")
        assert up.status_code == 200 and up.json()["checks"]["janus"] == "ok", up.text
        janus.stop()
        try:
            down = api.get("/api/ready")
            assert down.status_code == 503, down.text
            assert down.json()["checks"]["janus"].startswith("unreachable"), down.text
        finally:
            janus.start()
        assert api.get("/api/ready").json()["checks"]["janus"] == "ok"


@pytest.mark.slow
async def test_janus_restarting_is_noticed_and_the_mountpoint_made_again(
    server: LiveServer, tenant: Tenant, janus: Janus
):
    asset_id, token = uav_with_camera(tenant, httpx.Client(base_url=server.url))
    pub = rtp_publisher(server, asset_id, token)
    sending = asyncio.create_task(pub.run())
    try:
        await eventually(lambda: pub.packets > 20, within=20, what="RTP sent to Janus")
        janus.stop()
        janus.start()
        # the server's event poll finds its session gone and makes it and the mountpoints again;
        # the agent asks for its target again within recheck_s and keeps sending
        viewer = JanusViewer(server.url, asset_id, tenant.tokens["viewer"])

        async def watching() -> bool:
            r = await viewer.start()
            return r.status_code == 201

        await eventually(
            watching, within=30, what="a viewer admitted after the restart", interval=1
        )
        await eventually(lambda: viewer.frames >= 20, within=30, what="frames after the restart")
        await viewer.close()
    finally:
        sending.cancel()
        await pub.track.aclose()


def test_the_private_network_is_what_janus_uses(janus: Janus):
    log = (janus.folder / "janus.log").read_text(errors="replace")
    assert "Error gathering candidates" not in log
    assert Path(janus.folder / "cfg" / "janus.jcfg").exists()


@pytest.mark.slow
async def test_headless_chromium_decodes_more_than_60_frames_through_janus(
    server: LiveServer, tenant: Tenant
):
    from playwright.async_api import async_playwright

    from tests.video.test_viewer_browser import CHROMIUM, CHROMIUM_ARGS

    camera = {"width": 640, "height": 480, "fps": 30}
    asset_id, token = uav_with_camera(tenant, httpx.Client(base_url=server.url), camera)
    track = CameraTrack(pattern(640, 480), 640, 480, 30)
    pub = RtpPublisher(server.url, asset_id, lambda: token, track, recheck_s=2.0)
    sending = asyncio.create_task(pub.run())
    try:
        await eventually(lambda: pub.packets > 50, within=20, what="RTP sent to Janus")
        async with async_playwright() as p:
            browser = await p.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS)
            try:
                page = await browser.new_page()
                viewer = tenant.tokens["viewer"]
                await page.goto(f"{server.url}/video/viewer#asset={asset_id}&token={viewer}")
                await page.wait_for_function(
                    "window.aerobaseViewer && window.aerobaseViewer.frames > 60", timeout=60_000
                )
                state = await page.evaluate("window.aerobaseViewer")
                assert state["state"] == "live" and state["error"] is None, state
                assert (state["width"], state["height"]) == (640, 480), state
                assert "janus" in (await page.text_content("#info") or "")
            finally:
                await browser.close()
    finally:
        sending.cancel()
        await track.aclose()


@pytest.mark.slow
async def test_the_agent_switches_to_rtp_when_the_server_says_use_rtp(
    server: LiveServer, tenant: Tenant
):
    from asset_agent.config import AgentConfig
    from asset_agent.video.publish import video_publisher
    from sim.camera.server import CameraServer
    from tests.video.test_agent_video import WallClock

    camera = CameraServer(lambda: (0.0, 0.0, 6.0, 0.0, 0.0, 0.0), WallClock(), fps=15)
    port = await camera.start()
    asset_id, token = uav_with_camera(tenant, httpx.Client(base_url=server.url))
    config = AgentConfig.model_validate(
        {"video": {"enabled": True, "camera_port": port, "width": 320, "height": 240, "fps": 15}}
    )
    publisher = video_publisher(config, server.url, asset_id, lambda: token)
    assert publisher is not None
    running = asyncio.create_task(publisher.run())
    viewer = JanusViewer(server.url, asset_id, tenant.tokens["viewer"])
    try:
        await eventually(lambda: publisher.rtp.packets > 20, within=20, what="RTP from the agent")
        assert (await viewer.start()).status_code == 201
        await eventually(lambda: viewer.frames >= 20, within=30, what="the camera through Janus")
        assert viewer.sizes == {(320, 240)}
    finally:
        await viewer.close()
        running.cancel()
        await publisher.track.aclose()
        await camera.stop()
