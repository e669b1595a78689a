"""The agent's video: its configured source published to the server for as long as it runs."""

from __future__ import annotations

import logging
from collections.abc import Callable

from asset_agent.config import AgentConfig
from asset_agent.video.rtp import RtpPublisher
from asset_agent.video.source import CameraTrack, Images, sim_camera, video_file
from asset_agent.video.whip import UseRtp, WhipPublisher
from asynckit.loopback_ice import loopback_candidates_only

log = logging.getLogger(__name__)


def source_of(config: AgentConfig) -> Images | None:
    """The configured images: a file, else the camera stream ([video], else [precland])."""
    video = config.video
    if video.file is not None:
        return video_file(str(video.file.expanduser()))
    port = video.camera_port or config.precland.camera_port
    if port is None:
        return None
    return sim_camera(video.camera_host or config.precland.camera_host, port)


class VideoPublisher:
    """Publishes the camera the way the server's media path takes it: WHIP (the embedded relay)
    or, when the server answers `use_rtp` (Janus), plain RTP to the port it names."""

    def __init__(self, whip: WhipPublisher, rtp: RtpPublisher) -> None:
        self.whip, self.rtp = whip, rtp
        self.track = rtp.track

    async def run(self) -> None:
        """Publish until cancelled."""
        try:
            await self.whip.run()
        except UseRtp:
            log.info("the server's media path is Janus: sending RTP where it says")
            await self.whip.stop()
            await self.rtp.run()

    async def stop(self) -> None:
        """End a WHIP publication (RTP simply stops with run())."""
        await self.whip.stop()


def video_publisher(
    config: AgentConfig, server_url: str, asset_id: str, token: Callable[[], str | None]
) -> VideoPublisher | None:
    """The publisher of the asset's camera, or None when video is off or has no source."""
    video = config.video
    if not video.enabled:
        return None
    images = source_of(config)
    if images is None:
        log.warning("[video] is enabled but has no source (file or camera_port)")
        return None
    if video.allow_loopback_ice:
        loopback_candidates_only()
    track = CameraTrack(images, video.width, video.height, video.fps)
    url = f"{server_url.rstrip('/')}/api/v1/assets/{asset_id}/video/whip"
    return VideoPublisher(
        WhipPublisher(url, token, track), RtpPublisher(server_url, asset_id, token, track)
    )
