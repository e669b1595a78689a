"""The embedded media path: WHIP in and WHEP out through aiortc peers inside the server.

Frames are forwarded encoded (`server/video/forward.py`): one publisher's VP8 frames reach every
viewer without a decode or an encode in the server. One server process holds an asset's stream,
so this path serves one replica; the Janus path is the one for several (frontend_api.md).
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import uuid
from collections.abc import Callable
from typing import Any

from aiortc import (
    RTCConfiguration,
    RTCPeerConnection,
    RTCRtpSender,
    RTCSessionDescription,
)
from aiortc.sdp import candidate_from_sdp

from server.kit.errors import BadRequest, Conflict, NotFound, Unprocessable
from server.kit.metrics import VIDEO_PUBLISHERS, VIDEO_VIEWERS
from server.video.camera import CameraDescription
from server.video.errors import ViewerLimit
from server.video.forward import Channel, ForwardTrack, tap_receiver
from server.video.gateway import Negotiated, RtpTarget, StreamStatus
from server.video.recording import Recorder, Recording

log = logging.getLogger(__name__)

CONNECT_TIMEOUT_S = 30.0  # a peer that has not connected by then is closed (a vanished viewer)


def _vp8_only(pc: RTCPeerConnection) -> None:
    """Negotiate VP8 on every video transceiver: the relay forwards VP8 as the asset sent it."""
    vp8 = [
        c for c in RTCRtpSender.getCapabilities("video").codecs if c.mimeType.lower() == "video/vp8"
    ]
    for transceiver in pc.getTransceivers():
        if transceiver.kind == "video":
            transceiver.setCodecPreferences(vp8)


async def _answer(pc: RTCPeerConnection, offer: str, prepare: Callable[[], None]) -> str:
    """Apply the offer, let `prepare` add tracks, answer; bad SDP is the client's error."""
    try:
        await pc.setRemoteDescription(RTCSessionDescription(sdp=offer, type="offer"))
    except Exception as err:  # aiortc raises ValueError, KeyError, ... on malformed SDP
        raise BadRequest(f"the SDP offer cannot be read: {err}", code="bad_offer") from err
    if not any(t.kind == "video" for t in pc.getTransceivers()):
        raise Unprocessable("the offer has no video section", code="no_video")
    prepare()
    _vp8_only(pc)
    try:
        await pc.setLocalDescription(await pc.createAnswer())
    except Exception as err:
        raise Unprocessable(
            f"no answer to this offer (it must accept VP8): {err}", code="bad_offer"
        ) from err
    return pc.localDescription.sdp


class _Peer:
    """One negotiated peer connection and what ends it."""

    def __init__(self, pc: RTCPeerConnection, on_end: Callable[[], Any]) -> None:
        self.pc = pc
        self.connected = asyncio.Event()
        self._on_end = on_end

        @pc.on("connectionstatechange")
        async def _changed() -> None:
            if pc.connectionState == "connected":
                self.connected.set()
            elif pc.connectionState in ("failed", "closed"):
                await self._end()

        self._reaper = asyncio.create_task(self._reap())

    async def _reap(self) -> None:
        with contextlib.suppress(TimeoutError):
            await asyncio.wait_for(self.connected.wait(), CONNECT_TIMEOUT_S)
            return
        log.info("video peer never connected; closing it")
        await self._end()

    async def _end(self) -> None:
        result = self._on_end()
        if asyncio.iscoroutine(result):
            await result

    async def close(self) -> None:
        if self._reaper is not asyncio.current_task():
            self._reaper.cancel()
        await self.pc.close()


class EmbeddedRelay:
    """The embedded media path (`MediaGateway`)."""

    name = "embedded"
    viewer_offers = True

    def __init__(
        self, rtc_config: Callable[[], RTCConfiguration], recording: Recording | None = None
    ) -> None:
        self._rtc_config = rtc_config
        self._recording = recording
        self._recorders: dict[uuid.UUID, Recorder] = {}
        self._retention: asyncio.Task[None] | None = None
        self._channels: dict[uuid.UUID, Channel] = {}
        self._publishers: dict[uuid.UUID, tuple[uuid.UUID, _Peer]] = {}
        self._viewers: dict[uuid.UUID, tuple[uuid.UUID, _Peer, ForwardTrack]] = {}
        # per viewer or publication session: what to call once it ends (`on_end`)
        self._on_end: dict[uuid.UUID, Callable[[], None]] = {}
        self._tasks: set[asyncio.Future[None]] = set()  # keyframe requests in flight

    def _channel(self, asset_id: uuid.UUID) -> Channel:
        return self._channels.setdefault(asset_id, Channel())

    async def publish(
        self,
        asset_id: uuid.UUID,
        offer: str,
        camera: CameraDescription,
        on_end: Callable[[], None] | None = None,
    ) -> Negotiated:
        """The asset's WHIP offer → answer; the previous publication, if any, ends."""
        session_id = uuid.uuid4()
        pc = RTCPeerConnection(self._rtc_config())
        channel = self._channel(asset_id)
        token = object()

        def prepare() -> None:
            for t in pc.getTransceivers():
                if t.kind == "video":
                    t.direction = "recvonly"

        try:
            answer = await _answer(pc, offer, prepare)
        except Exception:
            await pc.close()
            raise
        receiver = next(t.receiver for t in pc.getTransceivers() if t.kind == "video")
        tap_receiver(receiver, channel.sink_for(token))

        def request_keyframe() -> None:
            sources = receiver.getSynchronizationSources()
            if sources:
                task = asyncio.ensure_future(receiver._send_rtcp_pli(sources[0].source))
                self._tasks.add(task)
                task.add_done_callback(self._tasks.discard)

        previous = self._publishers.pop(asset_id, None)
        channel.attach(token, request_keyframe)
        await self._record(asset_id, channel)
        peer = _Peer(pc, lambda: self._ended_publication(asset_id, session_id, token))
        if on_end is not None:
            self._on_end[session_id] = on_end
        if previous is None:
            VIDEO_PUBLISHERS.inc()
        self._publishers[asset_id] = (session_id, peer)
        if previous is not None:
            self._ended(previous[0])
            await previous[1].close()
        log.info("video published", extra={"asset_id": str(asset_id), "session": str(session_id)})
        return Negotiated(session_id, answer)

    async def _record(self, asset_id: uuid.UUID, channel: Channel) -> None:
        """Start recording the asset's publication (a new segment; the previous one ends)."""
        if self._recording is None:
            return
        await self._stop_recording(asset_id, channel)
        recorder = Recorder(
            self._recording.folder, asset_id, self._recording.segment_s, channel.request_keyframe
        )
        self._recorders[asset_id] = recorder
        channel.listeners.append(recorder.offer)
        if self._retention is None:
            self._retention = asyncio.create_task(self._recording.retention_loop())

    async def _stop_recording(self, asset_id: uuid.UUID, channel: Channel) -> None:
        recorder = self._recorders.pop(asset_id, None)
        if recorder is not None:
            with contextlib.suppress(ValueError):
                channel.listeners.remove(recorder.offer)
            await asyncio.to_thread(recorder.close)

    async def _ended_publication(
        self, asset_id: uuid.UUID, session_id: uuid.UUID, token: object
    ) -> None:
        channel = self._channel(asset_id)
        channel.detach(token)
        current = self._publishers.get(asset_id)
        if current is not None and current[0] == session_id:
            del self._publishers[asset_id]
            VIDEO_PUBLISHERS.dec()
            self._ended(session_id)
            await self._stop_recording(asset_id, channel)
            await current[1].close()

    async def unpublish(self, asset_id: uuid.UUID, session_id: uuid.UUID) -> None:
        """End the asset's publication `session_id`."""
        current = self._publishers.get(asset_id)
        if current is None or current[0] != session_id:
            raise NotFound("no such publication of this asset")
        await current[1].close()  # connectionstatechange → closed → _ended_publication

    def _ended(self, session_id: uuid.UUID) -> None:
        """Call the session's `on_end`, once."""
        on_end = self._on_end.pop(session_id, None)
        if on_end is not None:
            on_end()

    async def view(
        self,
        asset_id: uuid.UUID,
        offer: str,
        max_viewers: int,
        on_end: Callable[[], None] | None = None,
    ) -> Negotiated:
        """A viewer's WHEP offer → answer; frames follow from the next keyframe."""
        channel = self._channel(asset_id)
        if len(channel.tracks) >= max_viewers:
            raise ViewerLimit(f"this stream has its {max_viewers} viewers", retry_after_s=5)
        session_id = uuid.uuid4()
        pc = RTCPeerConnection(self._rtc_config())
        track = ForwardTrack(channel.request_keyframe)
        senders: list[Any] = []

        def prepare() -> None:
            senders.append(pc.addTrack(track))

        try:
            answer = await _answer(pc, offer, prepare)
        except Exception:
            track.stop()
            await pc.close()
            raise
        # a viewer's PLI asks the publisher, since this sender has no encoder to refresh
        senders[0]._send_keyframe = channel.request_keyframe
        if len(channel.tracks) >= max_viewers:  # others were admitted while this one negotiated
            track.stop()
            await pc.close()
            raise ViewerLimit(f"this stream has its {max_viewers} viewers", retry_after_s=5)
        channel.tracks.add(track)
        peer = _Peer(pc, lambda: self._drop_viewer(session_id))
        self._viewers[session_id] = (asset_id, peer, track)
        if on_end is not None:
            self._on_end[session_id] = on_end
        VIDEO_VIEWERS.inc()
        channel.request_keyframe()
        return Negotiated(session_id, answer)

    async def _drop_viewer(self, session_id: uuid.UUID) -> None:
        found = self._viewers.pop(session_id, None)
        if found is None:
            return
        VIDEO_VIEWERS.dec()
        self._ended(session_id)
        asset_id, peer, track = found
        self._channel(asset_id).tracks.discard(track)
        track.stop()
        await peer.close()

    def _viewer(self, asset_id: uuid.UUID, session_id: uuid.UUID) -> _Peer:
        found = self._viewers.get(session_id)
        if found is None or found[0] != asset_id:
            raise NotFound("no such viewer session of this asset")
        return found[1]

    async def trickle(self, asset_id: uuid.UUID, session_id: uuid.UUID, fragment: str) -> None:
        """Add the candidates of an SDP fragment (`a=candidate:` lines) to a viewer's peer."""
        peer = self._viewer(asset_id, session_id)
        mid = next(
            (line[6:].strip() for line in fragment.splitlines() if line.startswith("a=mid:")),
            None,
        )
        transceivers = peer.pc.getTransceivers()
        mid = mid or (transceivers[0].mid if transceivers else None)
        for line in fragment.splitlines():
            if not line.startswith("a=candidate:"):
                continue
            try:
                candidate = candidate_from_sdp(line[len("a=candidate:") :].strip())
            except (ValueError, IndexError) as err:
                raise BadRequest(f"unreadable candidate: {line!r}", code="bad_candidate") from err
            candidate.sdpMid = mid
            await peer.pc.addIceCandidate(candidate)

    async def stop(self, asset_id: uuid.UUID, session_id: uuid.UUID) -> None:
        """End a viewer's session."""
        self._viewer(asset_id, session_id)
        await self._drop_viewer(session_id)

    async def answer(self, asset_id: uuid.UUID, session_id: uuid.UUID, sdp: str) -> None:
        """Viewers offer on this path; there is no answer to take."""
        self._viewer(asset_id, session_id)
        raise Conflict("on the embedded path the viewer offers (POST); nothing to answer")

    async def rtp_target(self, asset_id: uuid.UUID, camera: CameraDescription) -> RtpTarget:
        """The embedded path takes WHIP, not plain RTP."""
        raise Conflict(
            "this server's media path is the embedded relay: publish with WHIP", code="use_whip"
        )

    async def status(self, asset_id: uuid.UUID) -> StreamStatus:
        """Live when a publication feeds the channel; viewers admitted; fps arriving."""
        channel = self._channels.get(asset_id)
        if channel is None:
            return StreamStatus(live=False, viewers=0)
        return StreamStatus(live=channel.live, viewers=len(channel.tracks), fps=channel.fps())

    async def close(self) -> None:
        """End every peer (the server stops)."""
        for session_id in list(self._viewers):
            await self._drop_viewer(session_id)
        for session_id, peer in list(self._publishers.values()):
            self._ended(session_id)
            await peer.close()
        VIDEO_PUBLISHERS.dec(len(self._publishers))
        self._publishers.clear()
        for asset_id in list(self._recorders):
            await self._stop_recording(asset_id, self._channel(asset_id))
        if self._retention is not None:
            self._retention.cancel()
