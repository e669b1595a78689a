"""Building the configured media path at start-up."""

from __future__ import annotations

from aiortc import RTCConfiguration

from asynckit.loopback_ice import allow_loopback_candidates
from server.config import Settings
from server.video.gateway import MediaGateway


def make_gateway(settings: Settings) -> MediaGateway:
    """The media path the settings choose (the embedded relay by default)."""
    if settings.effective_video_path == "janus":
        raise RuntimeError("the Janus media path is not built yet (issue 15); unset JANUS_URL")
    if settings.video_ice_loopback:
        allow_loopback_candidates()

    def rtc_config() -> RTCConfiguration:
        # The relay answers with its host candidates only: the server is reachable at its own
        # addresses (STUN and TURN are for the viewers behind NAT, who get them from
        # GET .../video). Always a list: with None aiortc falls back to a public STUN server.
        return RTCConfiguration(iceServers=[])

    from server.video.embedded import EmbeddedRelay

    return EmbeddedRelay(rtc_config)
