"""Decisions about live video: who may publish and watch which asset's stream, and through what."""

from __future__ import annotations

import contextlib
import json
import re
import uuid
from collections.abc import Awaitable
from datetime import UTC, datetime
from pathlib import Path

from server.assets.models import Asset, AssetKind
from server.assets.service import AssetService
from server.config import Settings
from server.kit.errors import Forbidden, NotFound, Unprocessable
from server.kit.principal import Principal
from server.kit.service import Service
from server.kit.uow import UnitOfWork
from server.realtime.hub import Hub
from server.video.announce import announce
from server.video.camera import camera_of, has_camera
from server.video.errors import ViewerLimit
from server.video.gateway import MediaGateway, Negotiated
from server.video.ice import ice_servers
from server.video.schemas import IceServerOut, RecordingOut, RtpTargetOut, VideoOut

MAX_SDP_BYTES = 64 * 1024
RTP_LIVE_WITHIN_S = 15.0  # after handing out an RTP target: how long the media may take to arrive
SEGMENT_NAME = re.compile(r"^(\d{8}T\d{6}\.\d{6}Z)\.(webm|times\.jsonl)$")


def whep_path(asset_id: uuid.UUID) -> str:
    """The WHEP endpoint of an asset's stream."""
    return f"/api/v1/assets/{asset_id}/video/whep"


def whip_path(asset_id: uuid.UUID) -> str:
    """The WHIP endpoint the asset publishes to."""
    return f"/api/v1/assets/{asset_id}/video/whip"


def check_sdp(body: bytes, allow_empty: bool = False) -> str:
    """The body as SDP text (422 when it is not; empty allowed where the gateway offers)."""
    if len(body) > MAX_SDP_BYTES:
        raise Unprocessable(f"an SDP body is at most {MAX_SDP_BYTES} bytes", code="bad_offer")
    try:
        text = body.decode("utf-8")
    except UnicodeDecodeError as err:
        raise Unprocessable("the SDP body is not UTF-8", code="bad_offer") from err
    if allow_empty and not text.strip():
        return ""
    if not text.lstrip().startswith("v=0"):
        raise Unprocessable(
            "the body is not an SDP offer (it must start with v=0)", code="bad_offer"
        )
    return text


class VideoService(Service):
    """Describes, publishes and views the streams of the caller's organisation's UAVs."""

    def __init__(
        self,
        uow: UnitOfWork,
        principal: Principal,
        settings: Settings,
        gateway: MediaGateway,
        hub: Hub | None = None,
    ) -> None:
        super().__init__(uow, principal)
        self.settings = settings
        self.gateway = gateway
        self.hub = hub  # viewers and publications end with the caller's session through it
        self.assets = AssetService(uow, principal, settings)

    async def _uav(self, asset_id: uuid.UUID, camera: bool = True) -> Asset:
        """The UAV (404 for another organisation's asset or another kind); with `camera`, 404 too
        for a UAV described as having none (its sessions may still end, its recordings be read)."""
        asset = await self.assets.get(asset_id)  # NotFound for another organisation's asset
        if asset.kind != AssetKind.uav:
            raise NotFound("this asset has no camera stream (it is not a UAV)", code="no_video")
        if camera and not has_camera(asset.attributes):
            raise NotFound(
                "this UAV has no camera (its attributes.camera is false)", code="no_camera"
            )
        return asset

    async def require_stream(self, asset_id: uuid.UUID) -> None:
        """404 unless the asset is a UAV of the caller's organisation (before a body is read)."""
        await self._uav(asset_id)

    async def require_publisher(self, asset_id: uuid.UUID) -> None:
        """403/404 unless the caller is this asset (before a body is read)."""
        self._check_publisher(asset_id)
        await self._uav(asset_id)

    async def describe(self, asset_id: uuid.UUID) -> VideoOut:
        """The stream, its viewers and the ICE servers (with TURN credentials) to watch it."""
        asset = await self._uav(asset_id)
        camera = camera_of(asset.attributes)
        status = await self.gateway.status(asset_id)
        user = str(self.principal.user_id or self.principal.asset_id)
        return VideoOut(
            asset_id=asset.id,
            state="live" if status.live else "offline",
            path=self.settings.effective_video_path,
            codec=camera.codec,
            width=camera.width,
            height=camera.height,
            fps=camera.fps,
            measured_fps=round(status.fps, 1) if status.fps is not None else None,
            bitrate_kbps=camera.bitrate_kbps,
            viewers=status.viewers,
            max_viewers=self.settings.video_max_viewers,
            whep_url=whep_path(asset.id),
            viewer_offers=self.gateway.viewer_offers,
            ice_servers=[
                IceServerOut(urls=s.urls, username=s.username, credential=s.credential)
                for s in ice_servers(self.settings, user)
            ],
        )

    async def view(self, asset_id: uuid.UUID, offer: str) -> Negotiated:
        """Open a viewer session (WHEP)."""
        await self._uav(asset_id)
        hold = self.hub.hold(self.principal.session_id, "video_viewer") if self.hub else None
        try:
            opened = await self.gateway.view(
                asset_id,
                offer,
                self.settings.video_max_viewers,
                on_end=hold.release if hold else None,
            )
        except ViewerLimit as err:  # the path knows the limit is reached; the settings say when
            raise ViewerLimit(err.message, self.settings.video_retry_after_s) from None
        if hold is not None:  # the session's end stops the viewer, as it closes its sockets
            hold.start(lambda: self._quietly(self.gateway.stop(asset_id, opened.session_id)))
        return opened

    @staticmethod
    async def _quietly(step: Awaitable[None]) -> None:
        with contextlib.suppress(NotFound):  # it ended meanwhile
            await step

    async def answer(self, asset_id: uuid.UUID, session_id: uuid.UUID, sdp: str) -> None:
        """A viewer's SDP answer to the gateway's offer (Janus path)."""
        await self._uav(asset_id)
        await self.gateway.answer(asset_id, session_id, sdp)

    async def trickle(self, asset_id: uuid.UUID, session_id: uuid.UUID, fragment: str) -> None:
        """Trickled ICE candidates of a viewer session."""
        await self._uav(asset_id)
        await self.gateway.trickle(asset_id, session_id, fragment)

    async def stop(self, asset_id: uuid.UUID, session_id: uuid.UUID) -> None:
        """End a viewer session."""
        await self._uav(asset_id, camera=False)
        await self.gateway.stop(asset_id, session_id)

    def _check_publisher(self, asset_id: uuid.UUID) -> None:
        if self.principal.kind != "asset":
            raise Forbidden("only the asset itself publishes its video", code="not_the_asset")
        if self.principal.asset_id != asset_id:
            raise NotFound(f"asset {asset_id} not found")

    async def publish(self, asset_id: uuid.UUID, offer: str) -> Negotiated:
        """The asset's own WHIP publish (a user, or another asset, may not)."""
        self._check_publisher(asset_id)
        asset = await self._uav(asset_id)
        hold = self.hub.hold(self.principal.session_id, "video_publisher") if self.hub else None
        hub, gateway = self.hub, self.gateway  # not self: this request's unit of work ends first

        def ended() -> None:
            if hold is not None:
                hold.release()
            if hub is not None:
                announce(hub.broker, gateway, asset_id)

        opened = await self.gateway.publish(
            asset_id, offer, camera_of(asset.attributes), on_end=ended
        )
        if hold is not None:  # the asset's session ending (a new config, removal) ends it
            hold.start(lambda: self._quietly(self.gateway.unpublish(asset_id, opened.session_id)))
        self._announce(asset_id)
        return opened

    def _announce(self, asset_id: uuid.UUID, until_live_s: float = 0.0) -> None:
        """Tell the asset's followers its video state (`video_state` on /ws/operator)."""
        if self.hub is not None:
            announce(self.hub.broker, self.gateway, asset_id, until_live_s)

    async def rtp_target(self, asset_id: uuid.UUID) -> RtpTargetOut:
        """The asset asks where to send its RTP (Janus path): the mountpoint's port."""
        self._check_publisher(asset_id)
        asset = await self._uav(asset_id)
        camera = camera_of(asset.attributes)
        target = await self.gateway.rtp_target(asset_id, camera)
        self._announce(asset_id, until_live_s=RTP_LIVE_WITHIN_S)  # once its media reaches Janus
        return RtpTargetOut(
            host=target.host,
            port=target.port,
            payload_type=target.payload_type,
            codec=camera.codec,
            width=camera.width,
            height=camera.height,
            fps=camera.fps,
            bitrate_kbps=camera.bitrate_kbps,
        )

    async def unpublish(self, asset_id: uuid.UUID, session_id: uuid.UUID) -> None:
        """The asset ends its publication."""
        self._check_publisher(asset_id)
        await self.gateway.unpublish(asset_id, session_id)

    def _recording_folder(self, asset_id: uuid.UUID) -> Path | None:
        root = self.settings.video_record_dir
        return None if root is None else root / str(asset_id)

    async def recordings(self, asset_id: uuid.UUID) -> list[RecordingOut]:
        """The asset's recorded segments, newest first (empty when recording is off)."""
        await self._uav(asset_id, camera=False)
        return recorded_segments(self.settings.video_record_dir, asset_id)

    async def recording_file(self, asset_id: uuid.UUID, name: str) -> Path:
        """A segment or its times file (NotFound for any other name)."""
        await self._uav(asset_id, camera=False)
        folder = self._recording_folder(asset_id)
        if folder is None or SEGMENT_NAME.match(name) is None or not (folder / name).is_file():
            raise NotFound(f"no recording {name!r} of this asset")
        return folder / name


def _last_frame_time(times: Path) -> datetime | None:
    """The receive time of a segment's last frame (its times file's last line), None when none."""
    try:
        with times.open("rb") as f:
            f.seek(0, 2)
            f.seek(max(0, f.tell() - 512))
            tail = f.read().decode("utf-8", errors="replace")
    except OSError:
        return None
    for line in reversed(tail.splitlines()):
        try:
            t = json.loads(line)["t"]
        except (ValueError, KeyError, TypeError):
            continue  # a line being written, or cut by the seek
        if isinstance(t, int) and not isinstance(t, bool):
            return datetime.fromtimestamp(t / 1000, UTC)
    return None


def recorded_segments(
    root: Path | None,
    asset_id: uuid.UUID,
    start: datetime | None = None,
    end: datetime | None = None,
) -> list[RecordingOut]:
    """The asset's recorded segments under `root`, newest first; with `start` and `end`, only
    those whose frames (first to last, server receive times) overlap [start, end]."""
    folder = None if root is None else root / str(asset_id)
    if folder is None or not folder.is_dir():
        return []
    out = []
    base = f"/api/v1/assets/{asset_id}/video/recordings"
    for path in sorted(folder.glob("*.webm"), reverse=True):
        found = SEGMENT_NAME.match(path.name)
        if found is None:
            continue
        started = datetime.strptime(found[1], "%Y%m%dT%H%M%S.%fZ").replace(tzinfo=UTC)
        times = path.with_suffix(".times.jsonl")
        ended = _last_frame_time(times)
        if ended is not None:  # its times are whole milliseconds; the name has microseconds
            ended = max(ended, started)
        if end is not None and started > end:
            continue
        if start is not None and (ended or started) < start:
            continue
        try:
            size = path.stat().st_size
        except OSError:  # deleted by the retention meanwhile
            continue
        out.append(
            RecordingOut(
                name=path.name,
                started_at=started,
                ended_at=ended,
                bytes=size,
                url=f"{base}/{path.name}",
                times_url=f"{base}/{times.name}",
            )
        )
    return out
