"""Plain RTP to a media gateway (the Janus path): ask the server where, encode once, send.

The paper's handshake (§2.2.2): `POST .../video/rtp` makes (or finds) the asset's Janus
mountpoint and answers its host and port; the agent encodes its camera once (VP8 with PyAV, a
keyframe every second: a viewer joining Janus waits for one, and there is no RTCP path back to ask)
and sends RFC 7741 packets there over UDP. The target is asked again every `recheck_s`, so a Janus
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

import av
import httpx
from aiortc.rtp import RtpPacket

from asset_agent.video.source import TIME_BASE, CameraTrack

log = logging.getLogger(__name__)

MAX_PAYLOAD = 1200


def vp8_payloads(frame: bytes, picture_id: int) -> list[bytes]:
    """RFC 7741 payloads of one frame: descriptor (X, S on the first, a 15-bit PictureID)."""
    out = []
    for i, pos in enumerate(range(0, len(frame), MAX_PAYLOAD - 4)):
        descriptor = bytes(
            [0x90 if i == 0 else 0x80, 0x80, 0x80 | (picture_id >> 8) & 0x7F, picture_id & 0xFF]
        )
        out.append(descriptor + frame[pos : pos + MAX_PAYLOAD - 4])
    return out


class Vp8Encoder:
    """One libvpx encoder for the stream: realtime, CBR at the camera's bitrate, GOP of 1 s."""

    def __init__(self, width: int, height: int, fps: float, bitrate_kbps: int) -> None:
        self.codec = av.CodecContext.create("libvpx", "w")
        self.codec.width, self.codec.height = width, height
        self.codec.pix_fmt = "yuv420p"
        self.codec.bit_rate = bitrate_kbps * 1000
        self.codec.gop_size = max(1, round(fps))
        self.codec.time_base = TIME_BASE  # CameraTrack's pts; rate control needs the real clock
        self.codec.options = {"deadline": "realtime", "cpu-used": "8", "lag-in-frames": "0"}

    def encode(self, frame: av.VideoFrame) -> list[bytes]:
        """The encoded frame(s) for one picture."""
        frame = frame.reformat(format="yuv420p") if frame.format.name != "yuv420p" else frame
        return [bytes(p) for p in self.codec.encode(frame)]


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
        seq, picture_id, asked_at = random.getrandbits(16), random.getrandbits(15), -1e9
        try:
            while True:
                if loop.time() - asked_at > self.recheck_s:
                    try:
                        t = await self.ask()
                        self.target = (t["host"], int(t["port"]))
                        self.payload_type = int(t["payload_type"])
                        if encoder is None:
                            encoder = Vp8Encoder(
                                t["width"], t["height"], t["fps"], t["bitrate_kbps"]
                            )
                    except (httpx.HTTPError, KeyError, ValueError) as err:
                        log.warning("video RTP target unknown (%s); asking again", err)
                    asked_at = loop.time()
                frame = await self.track.recv()
                if encoder is None or self.target is None:
                    continue
                # CameraTrack stamps every frame in 1/90000 s
                ts = int(frame.pts or 0) & 0xFFFFFFFF
                for data in await asyncio.to_thread(encoder.encode, frame):
                    payloads = vp8_payloads(data, picture_id)
                    picture_id = (picture_id + 1) & 0x7FFF
                    for i, payload in enumerate(payloads):
                        packet = RtpPacket(
                            payload_type=self.payload_type,
                            sequence_number=seq,
                            timestamp=ts,
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
