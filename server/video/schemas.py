"""API shapes of live video."""

from __future__ import annotations

import uuid
from typing import Literal

from pydantic import BaseModel, Field

from server.kit.types import Timestamp

TURN_USER = "1764045600:0b6c3bb2-5f0d-4c3e-9a55-5d1c1f0e8a01"


class IceServerOut(BaseModel):
    """One entry for `RTCPeerConnection({iceServers})`; TURN entries carry time-limited credentials."""

    urls: list[str] = Field(
        description="STUN or TURN URLs of one server", examples=[["turn:turn.example.com:3478"]]
    )
    username: str | None = Field(
        default=None,
        description="TURN only: `<expiry unix time>:<user id>` (coturn use-auth-secret)",
        examples=[TURN_USER],
    )
    credential: str | None = Field(
        default=None,
        description="TURN only: base64(HMAC-SHA1(secret, username))",
        examples=["q2GkJ6mHcV1y3m8wqf4bXy3xS0E="],
    )


class VideoOut(BaseModel):
    """An asset's live stream and how to watch it."""

    asset_id: uuid.UUID
    state: Literal["live", "offline"] = Field(
        description="live: the asset is publishing; offline: it is not (viewers may still join "
        "and wait)",
        examples=["live"],
    )
    path: Literal["embedded", "janus"] = Field(
        description="the media path: the server's own relay, or the Janus gateway",
        examples=["embedded"],
    )
    codec: Literal["vp8"] = Field(description="the video codec", examples=["vp8"])
    width: int = Field(description="frame width in pixels (camera description)", examples=[640])
    height: int = Field(description="frame height in pixels (camera description)", examples=[480])
    fps: float = Field(description="the frame rate of the camera description", examples=[30.0])
    measured_fps: float | None = Field(
        default=None,
        description="frames per second arriving from the asset, when live (embedded path)",
        examples=[29.7],
    )
    bitrate_kbps: int = Field(description="the camera description's bitrate", examples=[1000])
    viewers: int = Field(description="viewer sessions of this stream now", examples=[2])
    max_viewers: int = Field(description="viewer sessions allowed per asset", examples=[10])
    whep_url: str = Field(
        description="where to POST to watch (WHEP)",
        examples=["/api/v1/assets/0b6c3bb2-5f0d-4c3e-9a55-5d1c1f0e8a01/video/whep"],
    )
    viewer_offers: bool = Field(
        description="true: POST your SDP offer to whep_url (WHEP); false (Janus path): POST an "
        "empty body, answer the SDP offer it returns with PATCH (application/sdp) to its Location",
        examples=[True],
    )
    ice_servers: list[IceServerOut] = Field(
        description="for RTCPeerConnection({iceServers}): STUN, and TURN with credentials"
    )


class RecordingOut(BaseModel):
    """One recorded segment (WebM, VP8 as the asset sent it) and its frame times."""

    name: str = Field(
        description="the segment's file name", examples=["20261125T024012.123456Z.webm"]
    )
    started_at: Timestamp  # the server's receive time of its first frame (frontend_api.md)
    ended_at: Timestamp | None = Field(
        default=None,
        description="when the server received the segment's last frame so far (UTC, server "
        "clock); null before its first frame is written",
    )
    bytes: int = Field(description="the segment's size", examples=[7340032])
    url: str = Field(
        description="the segment (video/webm)",
        examples=["/api/v1/assets/0b6c.../video/recordings/20261125T024012.123456Z.webm"],
    )
    times_url: str = Field(
        description="one JSON line per frame: pts (90 kHz) and t (unix ms, server clock)",
        examples=["/api/v1/assets/0b6c.../video/recordings/20261125T024012.123456Z.times.jsonl"],
    )


class RtpTargetOut(BaseModel):
    """Where the asset sends its RTP (Janus path) and what to send."""

    host: str = Field(description="the address to send RTP to", examples=["203.0.113.7"])
    port: int = Field(description="the UDP port Janus chose for the mountpoint", examples=[20004])
    payload_type: int = Field(description="the RTP payload type to use", examples=[96])
    codec: Literal["vp8"] = Field(description="the codec to send", examples=["vp8"])
    width: int = Field(description="frame width to send", examples=[640])
    height: int = Field(description="frame height to send", examples=[480])
    fps: float = Field(description="frame rate to send", examples=[30.0])
    bitrate_kbps: int = Field(description="target bitrate", examples=[1000])
