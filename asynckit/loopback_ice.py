"""A test and development switch: ICE host candidates on loopback, and only there.

aioice (`aioice.ice.get_host_addresses`) never offers 127.0.0.1, so on a host whose only interface
is `lo` no WebRTC peer (the server's relay, the agent's publisher, a test viewer) has a candidate
and nothing connects; on a host with other interfaces, peers that all run on it would still pair
over those. `loopback_candidates_only()` makes aioice offer 127.0.0.1 and nothing else, process-
wide, so everything on one machine (tests, the demo) talks over loopback. The server refuses it in
production (AEROBASE_VIDEO_ICE_LOOPBACK); the agent takes it from `[video]`.
"""

from __future__ import annotations

_switched = False


def loopback_candidates_only() -> None:
    """From now on this process's ICE host candidates are 127.0.0.1 only (idempotent)."""
    global _switched
    if _switched:
        return
    import aioice.ice

    def loopback(use_ipv4: bool, use_ipv6: bool) -> list[str]:
        return ["127.0.0.1"] if use_ipv4 else []

    aioice.ice.get_host_addresses = loopback
    _switched = True
