"""Building the configured media path at start-up."""

from __future__ import annotations

from urllib.parse import urlsplit

from aiortc import RTCConfiguration

from asynckit.loopback_ice import loopback_candidates_only
from server.config import Settings
from server.video.gateway import MediaGateway
from server.video.recording import Recording


def make_gateway(settings: Settings) -> MediaGateway:
    """The media path the settings choose (the embedded relay by default)."""
    if settings.effective_video_path == "janus":
        from server.video.janus import JanusGateway

        assert settings.janus_url is not None  # the settings check it
        rtp_host = settings.janus_rtp_host or (urlsplit(settings.janus_url).hostname or "127.0.0.1")
        return JanusGateway(settings.janus_url, rtp_host)
    if settings.video_ice_loopback:
        loopback_candidates_only()

    def rtc_config() -> RTCConfiguration:
        # The relay answers with its host candidates only: the server is reachable at its own
        # addresses (STUN and TURN are for the viewers behind NAT, who get them from
        # GET .../video). Always a list: with None aiortc falls back to a public STUN server.
        return RTCConfiguration(iceServers=[])

    from server.video.embedded import EmbeddedRelay

    recording = None
    if settings.video_record_dir is not None:
        recording = Recording(
            folder=settings.video_record_dir,
            segment_s=settings.video_record_segment_s,
            max_age_s=settings.video_record_max_age_days * 86400,
            max_bytes=settings.video_record_max_bytes,
        )
    return EmbeddedRelay(rtc_config, recording)
