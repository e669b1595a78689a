"""A test and development switch: let aioice offer 127.0.0.1 as an ICE host candidate.

aioice (`aioice.ice.get_host_addresses`) skips loopback, so on a host whose only interface is `lo`
no WebRTC peer (the server's relay, the agent's publisher, a test viewer) has a candidate and
nothing connects. `allow_loopback_candidates()` wraps that function once, process-wide. The server
refuses it in production (AEROBASE_VIDEO_ICE_LOOPBACK); the agent takes it from `[video]`.
"""

from __future__ import annotations

_allowed = False


def allow_loopback_candidates() -> None:
    """Offer 127.0.0.1 beside the host's other addresses from now on (idempotent)."""
    global _allowed
    if _allowed:
        return
    import aioice.ice

    original = aioice.ice.get_host_addresses

    def with_loopback(use_ipv4: bool, use_ipv6: bool) -> list[str]:
        found = original(use_ipv4, use_ipv6)
        return [*found, "127.0.0.1"] if use_ipv4 and "127.0.0.1" not in found else found

    aioice.ice.get_host_addresses = with_loopback
    _allowed = True
