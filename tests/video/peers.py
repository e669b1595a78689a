"""Test peers for live video: a publisher of synthetic frames and an in-process aiortc viewer.

Both speak the real protocols (WHIP and WHEP over HTTP, ICE/DTLS/SRTP over UDP) to a real server.
"""

from __future__ import annotations

import asyncio
import contextlib
from collections.abc import AsyncIterator
from dataclasses import dataclass, field
from typing import Any

import httpx
import numpy as np
from aiortc import RTCConfiguration, RTCPeerConnection, RTCSessionDescription
from aiortc.mediastreams import MediaStreamError

from asset_agent.video.source import CameraTrack
from asset_agent.video.whip import WhipPublisher


def pattern(width: int, height: int):  # type: ignore[no-untyped-def]
    """A factory of moving-bar test images (something a VP8 encoder must really encode)."""

    async def images() -> AsyncIterator[np.ndarray]:
        n = 0
        base = np.zeros((height, width, 3), dtype=np.uint8)
        base[:, :, 1] = np.linspace(0, 255, width, dtype=np.uint8)[None, :]
        while True:
            img = base.copy()
            x = (n * 7) % width
            img[:, x : x + 16, :] = 255
            n += 1
            yield img
            await asyncio.sleep(1 / 60)

    return images


def publisher(
    server_url: str, asset_id: str, token: str, w: int, h: int, fps: float
) -> WhipPublisher:
    """A WHIP publisher of the moving-bar pattern at w×h and fps."""
    track = CameraTrack(pattern(w, h), w, h, fps)
    return WhipPublisher(
        f"{server_url}/api/v1/assets/{asset_id}/video/whip", lambda: token, track, retry_s=0.5
    )


@dataclass
class Viewer:
    """A receive-only WHEP viewer counting the decoded frames it gets and their sizes."""

    server_url: str
    asset_id: str
    token: str | None
    frames: int = 0
    sizes: set[tuple[int, int]] = field(default_factory=set)
    location: str | None = None
    pc: RTCPeerConnection | None = None
    _reader: asyncio.Task[None] | None = None

    async def offer(self) -> httpx.Response:
        """Offer receive-only video; on 201 apply the answer and start counting frames."""
        pc = RTCPeerConnection(RTCConfiguration(iceServers=[]))
        pc.addTransceiver("video", direction="recvonly")

        @pc.on("track")
        def _track(track: Any) -> None:
            self._reader = asyncio.ensure_future(self._read(track))

        await pc.setLocalDescription(await pc.createOffer())
        headers = {"Content-Type": "application/sdp"}
        if self.token:
            headers["Authorization"] = f"Bearer {self.token}"
        async with httpx.AsyncClient(base_url=self.server_url, timeout=15) as c:
            r = await c.post(
                f"/api/v1/assets/{self.asset_id}/video/whep",
                content=pc.localDescription.sdp,
                headers=headers,
            )
        if r.status_code != 201:
            await pc.close()
            return r
        self.location = r.headers["location"]
        await pc.setRemoteDescription(RTCSessionDescription(sdp=r.text, type="answer"))
        self.pc = pc
        return r

    async def _read(self, track: Any) -> None:
        with contextlib.suppress(MediaStreamError):
            while True:
                frame = await track.recv()
                self.frames += 1
                self.sizes.add((frame.width, frame.height))

    async def close(self, delete: bool = True) -> None:
        """Stop viewing (DELETE the session unless `delete` is false: a vanished viewer)."""
        if delete and self.location:
            async with httpx.AsyncClient(base_url=self.server_url, timeout=15) as c:
                await c.delete(self.location, headers={"Authorization": f"Bearer {self.token}"})
        if self.pc is not None:
            await self.pc.close()
        if self._reader is not None:
            self._reader.cancel()
