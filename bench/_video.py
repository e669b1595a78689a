"""The pieces of bench/video.py: the stamped publisher images, the WHEP peers that count or
decode them, the VP8 encode reference and the set-up through the public API."""

from __future__ import annotations

import asyncio
import base64
import contextlib
import fractions
import time
import uuid
from collections.abc import AsyncIterator
from typing import Any

import av
import httpx
import numpy as np
from aiortc import RTCConfiguration, RTCPeerConnection, RTCSessionDescription
from aiortc.mediastreams import MediaStreamError

from assetlink.configfile import decrypt_config
from bench._aerobase import ASSET_PASSWORD, SUPER_PASSWORD
from server.video.forward import tap_receiver

BITS = 16
BLOCK_H = 24


class Stamped:
    """The publisher's images: a moving scene with the frame counter in its top rows."""

    def __init__(self, width: int, height: int, fps: float) -> None:
        self.width, self.height, self.fps = width, height, fps
        self.captured: dict[int, float] = {}
        scene = np.zeros((height, width, 3), dtype=np.uint8)
        scene[:, :, 1] = np.linspace(0, 200, width, dtype=np.uint8)[None, :]
        scene[:, :, 2] = np.linspace(0, 200, height, dtype=np.uint8)[:, None]
        self.scene = scene

    def image(self, n: int) -> np.ndarray:
        img = self.scene.copy()
        x = (n * 9) % self.width
        img[BLOCK_H:, x : x + 24, :] = 255
        block = self.width // BITS
        for b in range(BITS):
            img[:BLOCK_H, b * block : (b + 1) * block, :] = 255 if (n >> b) & 1 else 0
        return img

    async def images(self) -> AsyncIterator[np.ndarray]:
        n = 0
        start = time.perf_counter()
        while True:
            img = self.image(n & 0xFFFF)
            self.captured[n & 0xFFFF] = time.perf_counter()
            yield img
            n += 1
            delay = start + n / self.fps - time.perf_counter()
            await asyncio.sleep(max(0.0, delay))


def read_counter(gray: np.ndarray) -> int:
    block = gray.shape[1] // BITS
    n = 0
    for b in range(BITS):
        cell = gray[4 : BLOCK_H - 4, b * block + 4 : (b + 1) * block - 4]
        if float(cell.mean()) > 128:
            n |= 1 << b
    return n


class Peer:
    """A WHEP viewer: the probe decodes and reads counters; the others count encoded frames."""

    def __init__(self, url: str, asset_id: str, token: str, probe: Stamped | None) -> None:
        self.url, self.asset_id, self.token, self.probe = url, asset_id, token, probe
        self.frames = 0
        self.latencies: list[float] = []
        self.pc: RTCPeerConnection | None = None
        self.location: str | None = None
        self.task: asyncio.Task[None] | None = None

    async def start(self, api: httpx.AsyncClient, viewer_offers: bool) -> None:
        pc = RTCPeerConnection(RTCConfiguration(iceServers=[]))
        h = {"Content-Type": "application/sdp", "Authorization": f"Bearer {self.token}"}
        url = f"/api/v1/assets/{self.asset_id}/video/whep"

        @pc.on("track")
        def _track(track: Any) -> None:
            if self.probe is not None:
                self.task = asyncio.ensure_future(self._decode(track))

        if viewer_offers:  # WHEP: the viewer offers
            pc.addTransceiver("video", direction="recvonly")
            await pc.setLocalDescription(await pc.createOffer())
            r = await api.post(url, content=pc.localDescription.sdp, headers=h)
            if r.status_code != 201:
                raise RuntimeError(f"WHEP answered {r.status_code}: {r.text[:200]}")
            await pc.setRemoteDescription(RTCSessionDescription(sdp=r.text, type="answer"))
        else:  # Janus: the gateway offers, the viewer answers with PATCH
            r = await api.post(url, content=b"", headers=h)
            if r.status_code != 201:
                raise RuntimeError(f"WHEP answered {r.status_code}: {r.text[:200]}")
            await pc.setRemoteDescription(RTCSessionDescription(sdp=r.text, type="offer"))
            await pc.setLocalDescription(await pc.createAnswer())
            patched = await api.patch(
                r.headers["location"], content=pc.localDescription.sdp, headers=h
            )
            if patched.status_code != 204:
                raise RuntimeError(f"PATCH answered {patched.status_code}: {patched.text[:200]}")
        self.location = r.headers["location"]
        if self.probe is None:
            receiver = next(t.receiver for t in pc.getTransceivers() if t.kind == "video")
            tap_receiver(receiver, self._count)
        self.pc = pc

    def _count(self, data: bytes, timestamp: int) -> None:
        self.frames += 1

    async def _decode(self, track: Any) -> None:
        assert self.probe is not None
        with contextlib.suppress(MediaStreamError):
            while True:
                frame = await track.recv()
                now = time.perf_counter()
                self.frames += 1
                n = read_counter(frame.to_ndarray(format="gray"))
                sent = self.probe.captured.get(n)
                if sent is not None and 0 <= now - sent < 5:
                    self.latencies.append(now - sent)

    async def stop(self, api: httpx.AsyncClient) -> None:
        if self.location:
            with contextlib.suppress(httpx.HTTPError):
                await api.delete(self.location, headers={"Authorization": f"Bearer {self.token}"})
        if self.pc is not None:
            await self.pc.close()
        if self.task is not None:
            self.task.cancel()


def encode_reference(stamped: Stamped, frames: int) -> float:
    """CPU seconds per second of video for one VP8 encode of this stream (aiortc's settings)."""
    from aiortc.codecs.vpx import Vp8Encoder

    encoder = Vp8Encoder()
    images = [stamped.image(n) for n in range(frames)]
    t0 = time.process_time()
    for n, img in enumerate(images):
        f = av.VideoFrame.from_ndarray(img, format="bgr24")
        f.pts, f.time_base = n * 3000, fractions.Fraction(1, 90000)
        encoder.encode(f)
    return (time.process_time() - t0) / (frames / stamped.fps)


async def set_up(url: str, superuser: str, camera: dict[str, Any]) -> tuple[str, str, str]:
    """An organisation, a viewer, and a UAV with this camera: (asset id, asset token, viewer token)."""
    async with httpx.AsyncClient(base_url=url, timeout=60) as api:
        login = {"email": superuser, "password": SUPER_PASSWORD, "force": True}
        root = (await api.post("/api/v1/auth/login", json=login)).json()["access_token"]
        h = {"Authorization": f"Bearer {root}"}
        org = (
            await api.post(
                "/api/v1/organizations", json={"name": f"v-{uuid.uuid4().hex[:8]}"}, headers=h
            )
        ).json()
        root = (
            await api.post("/api/v1/auth/login", json={**login, "organization_id": org["id"]})
        ).json()["access_token"]
        h = {"Authorization": f"Bearer {root}"}
        email = f"viewer-{uuid.uuid4().hex[:6]}@bench.test"
        await api.post(
            "/api/v1/users",
            json={"email": email, "password": SUPER_PASSWORD, "role": "viewer"},
            headers=h,
        )
        viewer = (
            await api.post("/api/v1/auth/login", json={"email": email, "password": SUPER_PASSWORD})
        ).json()["access_token"]
        body = {
            "name": f"bench-cam-{uuid.uuid4().hex[:6]}",
            "kind": "uav",
            "password": ASSET_PASSWORD,
            "attributes": {"camera": camera},
        }
        created = (await api.post("/api/v1/assets", json=body, headers=h)).json()
        cfg = decrypt_config(base64.b64decode(created["config_file"]), ASSET_PASSWORD)
        r = await api.post("/api/v1/assets/login", json={"name": cfg.name, "secret": cfg.secret})
        return created["id"], r.json()["access_token"], viewer
