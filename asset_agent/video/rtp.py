"""Plain RTP to a media gateway (the Janus path): ask the server where, encode once, send.

The paper's handshake (§2.2.2): `POST .../video/rtp` makes (or finds) the asset's Janus
mountpoint and answers its host and port; the agent encodes its camera once (aiortc's VP8
encoder, which also packetises per RFC 7741; a keyframe every second: a viewer joining Janus waits
for one, and no RTCP path comes back to ask) and sends the packets there over UDP. The target is asked again every `recheck_s`, so a Janus
that restarted (new mountpoint, maybe a new port) is followed.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import random
import socket
from collections.abc import Callable
from dataclasses import dataclass, field

import httpx
from aiortc.codecs.vpx import Vp8Encoder
from aiortc.rtp import RtpPacket

from asset_agent.video.source import CameraTrack

log = logging.getLogger(__name__)

KEYFRAME_EVERY_S = 1.0


def make_encoder(bitrate_kbps: int) -> Vp8Encoder:
    """aiortc's VP8 encoder (libvpx realtime, CBR; it packetises per RFC 7741) at the camera's
    bitrate, within aiortc's 250 kb/s - 1.5 Mb/s."""
    encoder = Vp8Encoder()
    encoder.target_bitrate = bitrate_kbps * 1000
    return encoder


@dataclass
class RtpPublisher:
    """Sends one track as RTP to where the server says, for as long as it runs."""

    server_url: str
    asset_id: str
    token: Callable[[], str | None]
    track: CameraTrack
    recheck_s: float = 5.0
    packets: int = 0
    target: tuple[str, int] | None = None
    payload_type: int = 96
    _ssrc: int = field(default_factory=lambda: random.getrandbits(32))

    async def ask(self) -> dict:
        """POST .../video/rtp: the target and the stream's parameters."""
        token = self.token()
        headers = {"Authorization": f"Bearer {token}"} if token else {}
        url = f"{self.server_url.rstrip('/')}/api/v1/assets/{self.asset_id}/video/rtp"
        async with httpx.AsyncClient(timeout=15.0) as client:
            r = await client.post(url, headers=headers)
        r.raise_for_status()
        return dict(r.json())

    async def run(self) -> None:
        """Encode and send until cancelled; ask for the target again now and then."""
        loop = asyncio.get_running_loop()
        transport, _ = await loop.create_datagram_endpoint(
            asyncio.DatagramProtocol, family=socket.AF_INET
        )
        encoder: Vp8Encoder | None = None
        keyframe_every = 1
        seq, asked_at, count = random.getrandbits(16), -1e9, 0
        try:
            while True:
                if loop.time() - asked_at > self.recheck_s:
                    try:
                        t = await self.ask()
                        self.target = (t["host"], int(t["port"]))
                        self.payload_type = int(t["payload_type"])
                        if encoder is None:
                            encoder = make_encoder(int(t["bitrate_kbps"]))
                            keyframe_every = max(1, round(float(t["fps"]) * KEYFRAME_EVERY_S))
                    except (httpx.HTTPError, KeyError, ValueError) as err:
                        log.warning("video RTP target unknown (%s); asking again", err)
                    asked_at = loop.time()
                frame = await self.track.recv()
                if encoder is None or self.target is None:
                    continue
                # a keyframe every second: a viewer joining Janus waits for one, and no RTCP
                # path comes back from Janus to ask for it
                force = count % keyframe_every == 0
                count += 1
                payloads, ts = await asyncio.to_thread(encoder.encode, frame, force)
                for i, payload in enumerate(payloads):
                    packet = RtpPacket(
                        payload_type=self.payload_type,
                        sequence_number=seq,
                        timestamp=ts & 0xFFFFFFFF,
                        ssrc=self._ssrc,
                        payload=payload,
                    )
                    packet.marker = int(i == len(payloads) - 1)
                    with contextlib.suppress(OSError):
                        transport.sendto(packet.serialize(), self.target)
                    seq = (seq + 1) & 0xFFFF
                    self.packets += 1
        finally:
            transport.close()
