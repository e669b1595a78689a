"""A WHEP viewer with relay-only ICE, run as its own process by test_video_turn.py.

    python -m tests.video.relay_only_viewer SERVER_URL ASSET_ID TOKEN FRAMES

aiortc has no `iceTransportPolicy="relay"`; a peer with no host candidates is relay-only. This
process makes aioice find no host address (in its own memory only: the server and the publisher
in the test's process keep theirs), takes the ICE servers from GET .../video (coturn with the
server's time-limited credentials), watches until FRAMES frames have been decoded (or 40 s),
and prints one JSON line: frames, sizes, and the types of its local candidates.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import sys

import aioice.ice
import httpx
from aiortc import RTCConfiguration, RTCIceServer, RTCPeerConnection, RTCSessionDescription
from aiortc.mediastreams import MediaStreamError


def no_host_addresses(use_ipv4: bool, use_ipv6: bool) -> list[str]:
    """Relay-only: this peer offers no host (nor server-reflexive) candidate."""
    return []


async def watch(url: str, asset_id: str, token: str, want: int) -> dict[str, object]:
    aioice.ice.get_host_addresses = no_host_addresses
    h = {"Authorization": f"Bearer {token}"}
    async with httpx.AsyncClient(base_url=url, timeout=30) as c:
        desc = (await c.get(f"/api/v1/assets/{asset_id}/video", headers=h)).json()
        servers = [
            RTCIceServer(urls=s["urls"], username=s["username"], credential=s["credential"])
            for s in desc["ice_servers"]
            if s["username"]  # the TURN entry
        ]
        pc = RTCPeerConnection(RTCConfiguration(iceServers=servers))
        pc.addTransceiver("video", direction="recvonly")
        frames, sizes, done = 0, set(), asyncio.Event()

        async def read(track: object) -> None:
            nonlocal frames
            with contextlib.suppress(MediaStreamError):
                while True:
                    frame = await track.recv()  # type: ignore[attr-defined]
                    frames += 1
                    sizes.add(f"{frame.width}x{frame.height}")
                    if frames >= want:
                        done.set()

        tasks = []
        pc.on("track", lambda track: tasks.append(asyncio.ensure_future(read(track))))
        await pc.setLocalDescription(await pc.createOffer())
        offer = pc.localDescription.sdp
        types = sorted(
            {line.split(" typ ")[1].split()[0] for line in offer.splitlines() if " typ " in line}
        )
        r = await c.post(
            desc["whep_url"], content=offer, headers={**h, "Content-Type": "application/sdp"}
        )
        if r.status_code != 201:
            return {"error": f"WHEP {r.status_code}: {r.text[:200]}"}
        await pc.setRemoteDescription(RTCSessionDescription(sdp=r.text, type="answer"))
        with contextlib.suppress(TimeoutError):
            await asyncio.wait_for(done.wait(), 40)
        await c.delete(r.headers["location"], headers=h)
        await pc.close()
        for t in tasks:
            t.cancel()
        return {"frames": frames, "sizes": sorted(sizes), "candidate_types": types}


def main() -> None:
    url, asset_id, token, want = sys.argv[1:5]
    print(json.dumps(asyncio.run(watch(url, asset_id, token, int(want)))), flush=True)


if __name__ == "__main__":
    main()
