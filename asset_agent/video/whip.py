"""Publishing a track with WHIP (RFC 9725), and publishing it again whenever the peer drops.

`WhipPublisher.run()` offers send-only VP8, POSTs the offer (`application/sdp`, bearer token)
to the server's WHIP URL, applies the answer, and waits for the connection to fail or close; it
then publishes again after a back-off, so a link cut costs the viewers a pause, not a reload.
`stop()` DELETEs the session.
"""

from __future__ import annotations

import asyncio
import logging
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import httpx
from aiortc import (
    RTCConfiguration,
    RTCIceServer,
    RTCPeerConnection,
    RTCRtpSender,
    RTCSessionDescription,
)
from aiortc.mediastreams import MediaStreamTrack

log = logging.getLogger(__name__)


class _Lease(MediaStreamTrack):
    """The camera track as one peer sees it: a sender that ends stops this, not the camera."""

    kind = "video"

    def __init__(self, source: MediaStreamTrack) -> None:
        super().__init__()
        self.source = source

    async def recv(self) -> Any:
        """The camera's next frame."""
        return await self.source.recv()


class WhipError(Exception):
    """The server refused the publication (status and body in the message)."""


class UseRtp(Exception):
    """The server's media path takes plain RTP (Janus), not WHIP: ask POST .../video/rtp."""


@dataclass
class WhipPublisher:
    """Publishes one track to a WHIP endpoint and keeps it published."""

    url: str  # e.g. http://server/api/v1/assets/<id>/video/whip
    token: Callable[[], str | None]  # the asset session's bearer token (it may be renewed)
    track: MediaStreamTrack
    ice_servers: list[RTCIceServer] = field(default_factory=list)
    retry_s: float = 1.0
    max_retry_s: float = 10.0
    publications: int = 0  # successful publishes (a re-publish after a cut counts again)
    connected: asyncio.Event = field(default_factory=asyncio.Event)
    _pc: RTCPeerConnection | None = None
    _location: str | None = None

    async def publish_once(self) -> asyncio.Event:
        """One publication; returns an event set when its connection fails or closes."""
        pc = RTCPeerConnection(RTCConfiguration(iceServers=list(self.ice_servers)))
        ended = asyncio.Event()

        @pc.on("connectionstatechange")
        async def _changed() -> None:
            if pc.connectionState == "connected":
                self.connected.set()
            elif pc.connectionState in ("failed", "closed"):
                self.connected.clear()
                ended.set()

        transceiver = pc.addTransceiver(_Lease(self.track), direction="sendonly")
        vp8 = [
            c
            for c in RTCRtpSender.getCapabilities("video").codecs
            if c.mimeType.lower() == "video/vp8"
        ]
        transceiver.setCodecPreferences(vp8)
        try:
            await pc.setLocalDescription(await pc.createOffer())
            headers = {"Content-Type": "application/sdp"}
            token = self.token()
            if token:
                headers["Authorization"] = f"Bearer {token}"
            async with httpx.AsyncClient(timeout=15.0) as client:
                r = await client.post(self.url, content=pc.localDescription.sdp, headers=headers)
            if r.status_code == 409 and '"use_rtp"' in r.text:
                raise UseRtp(r.text[:300])
            if r.status_code != 201:
                raise WhipError(f"WHIP {r.status_code}: {r.text[:300]}")
            self._location = str(httpx.URL(self.url).join(r.headers.get("location", "")))
            await pc.setRemoteDescription(RTCSessionDescription(sdp=r.text, type="answer"))
        except BaseException:
            await pc.close()
            raise
        self._pc = pc
        self.publications += 1
        return ended

    async def run(self) -> None:
        """Publish, and publish again after every drop, until cancelled."""
        delay = self.retry_s
        while True:
            try:
                ended = await self.publish_once()
                delay = self.retry_s
                await ended.wait()
                log.info("video publication ended; publishing again")
            except (httpx.HTTPError, WhipError, OSError) as err:
                log.warning("video publish failed: %s; retrying in %.0f s", err, delay)
            await self._close_pc()
            await asyncio.sleep(delay)
            delay = min(delay * 2, self.max_retry_s)

    async def _close_pc(self) -> None:
        pc, self._pc = self._pc, None
        if pc is not None:
            await pc.close()

    async def stop(self) -> None:
        """End the publication (DELETE it on the server) and close the peer."""
        location, self._location = self._location, None
        if location:
            token = self.token()
            headers: dict[str, Any] = {"Authorization": f"Bearer {token}"} if token else {}
            try:
                async with httpx.AsyncClient(timeout=5.0) as client:
                    await client.delete(location, headers=headers)
            except httpx.HTTPError as err:
                log.info("WHIP DELETE failed (the server ends it when the peer goes): %s", err)
        await self._close_pc()
