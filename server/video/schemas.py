"""API shapes of live video."""

from __future__ import annotations

import uuid
from datetime import datetime
from typing import Literal

from pydantic import BaseModel, Field


class IceServerOut(BaseModel):
    """One entry for `RTCPeerConnection({iceServers})`; TURN entries carry time-limited credentials."""

    urls: list[str]
    username: str | None = None
    credential: str | None = None


class VideoOut(BaseModel):
    """An asset's live stream and how to watch it."""

    asset_id: uuid.UUID
    state: Literal["live", "offline"] = Field(
        description="live: the asset is publishing; offline: it is not (viewers may still join and wait)"
    )
    path: Literal["embedded", "janus"]
    codec: Literal["vp8"]
    width: int
    height: int
    fps: float = Field(description="the frame rate of the camera description")
    measured_fps: float | None = Field(
        default=None, description="frames per second arriving from the asset, when live"
    )
    bitrate_kbps: int
    viewers: int
    max_viewers: int
    whep_url: str
    viewer_offers: bool = Field(
        description="true: POST your SDP offer to whep_url (WHEP); false (Janus path): POST an "
        "empty body, answer the SDP offer it returns with PATCH (application/sdp) to its Location"
    )
    ice_servers: list[IceServerOut]


class RecordingOut(BaseModel):
    """One recorded segment (WebM, VP8 as the asset sent it) and its frame times."""

    name: str
    started_at: datetime
    bytes: int
    url: str = Field(description="the segment (video/webm)")
    times_url: str = Field(
        description="one JSON line per frame: pts (90 kHz) and t (unix ms, server clock)"
    )


class RtpTargetOut(BaseModel):
    """Where the asset sends its RTP (Janus path) and what to send."""

    host: str
    port: int
    payload_type: int
    codec: Literal["vp8"]
    width: int
    height: int
    fps: float
    bitrate_kbps: int
