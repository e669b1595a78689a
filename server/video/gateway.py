"""What a media path offers the video service: publish, view, trickle, stop, and a status."""

from __future__ import annotations

import uuid
from collections.abc import Callable
from dataclasses import dataclass
from typing import Literal, Protocol

from server.video.camera import CameraDescription


@dataclass(frozen=True)
class StreamStatus:
    """What a media path knows of one asset's stream."""

    live: bool
    viewers: int
    fps: float | None = None  # frames per second arriving from the asset, when live


@dataclass(frozen=True)
class Negotiated:
    """A session the path opened: its id and its SDP (the answer to the client's offer, or on the
    Janus path the gateway's offer, which the client answers with PATCH)."""

    session_id: uuid.UUID
    answer: str
    kind: Literal["answer", "offer"] = "answer"


@dataclass(frozen=True)
class RtpTarget:
    """Where an asset sends its plain RTP on the Janus path (the paper's handshake)."""

    host: str
    port: int
    payload_type: int
    codec: str


class MediaGateway(Protocol):
    """One media path (the embedded relay, Janus)."""

    name: str
    viewer_offers: bool  # True: WHEP as in RFC 9725 (the viewer offers); False: the gateway offers

    async def publish(
        self,
        asset_id: uuid.UUID,
        offer: str,
        camera: CameraDescription,
        on_end: Callable[[], None] | None = None,
    ) -> Negotiated:
        """The asset's WHIP offer → answer; replaces the asset's previous publication.
        `on_end` is called once when the publication ends, however it ends."""
        ...

    async def unpublish(self, asset_id: uuid.UUID, session_id: uuid.UUID) -> None:
        """End a publication (NotFound when it is not the asset's)."""
        ...

    async def view(
        self,
        asset_id: uuid.UUID,
        offer: str,
        max_viewers: int,
        on_end: Callable[[], None] | None = None,
    ) -> Negotiated:
        """A viewer's WHEP offer → answer (ViewerLimit when the asset has max_viewers).
        `on_end` is called once when the viewer's session ends, however it ends."""
        ...

    async def answer(self, asset_id: uuid.UUID, session_id: uuid.UUID, sdp: str) -> None:
        """A viewer's answer to the gateway's offer (paths whose gateway offers)."""
        ...

    async def rtp_target(self, asset_id: uuid.UUID, camera: CameraDescription) -> RtpTarget:
        """Where the asset sends plain RTP (paths that take RTP, not WHIP)."""
        ...

    async def trickle(self, asset_id: uuid.UUID, session_id: uuid.UUID, fragment: str) -> None:
        """Add a viewer's trickled ICE candidates (an SDP fragment)."""
        ...

    async def stop(self, asset_id: uuid.UUID, session_id: uuid.UUID) -> None:
        """End a viewer's session (NotFound when it is not one of the asset's)."""
        ...

    async def status(self, asset_id: uuid.UUID) -> StreamStatus:
        """The asset's stream as this path sees it."""
        ...

    async def close(self) -> None:
        """End every session (the server stops)."""
        ...
