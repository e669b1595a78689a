"""RTK corrections on the site's own network: the base daemon serves its reference receiver's RTCM3
stream on a local port and the UAV's agent injects from it, so with the server down the UAV keeps
its RTK fixed fix (through the server alone it falls to a plain 3D fix within 3 s); a third-party
rover (RTKLIB's str2str) reads the same stream (issue 46)."""

from __future__ import annotations

import asyncio
import time

import httpx
import pytest

from tests.conftest import LiveServer, Tenant, test_settings
from tests.e2e.harness import platform
from tests.polling import eventually
from tests.rtk import frames_in, stop, str2str

pytestmark = pytest.mark.slow  # whole processes end to end: not in the fast lane

RTK_FIXED = 6
OUTAGE_S = 10.0  # wall seconds watched with the server down: the fix would fall within 3


async def test_the_uav_keeps_rtk_fixed_with_the_server_down_on_the_bases_local_stream(
    database_url, superuser_email, tmp_path
):
    server = LiveServer(test_settings(database_url)).start()
    try:
        with httpx.Client(base_url=server.url) as sync_api:
            tenant = Tenant(sync_api, superuser_email, "rtk-local")
            async with platform(server.url, tenant, tmp_path, local_rtk=True) as p:
                corrections = p.agent.corrections
                assert corrections is not None
                await eventually(
                    lambda: p.copter.reading.fix_type == RTK_FIXED, 30, "an RTK fixed fix"
                )
                # both paths deliver while the server is up: the local one is injected, the
                # server's copies are not
                await eventually(lambda: corrections.skipped > 5, 20, "the server's copies")
                await asyncio.to_thread(server.stop)
                down = time.monotonic()
                local = corrections.injected["local"]
                fixes: set[int] = set()
                while time.monotonic() - down < OUTAGE_S:
                    fixes.add(p.copter.reading.fix_type)
                    await asyncio.sleep(0.05)
                assert fixes == {RTK_FIXED}, fixes
                assert not p.agent.link.connected
                assert corrections.injected["local"] > local + 5, corrections
                # every frame the agent injected reached the autopilot once, and only those
                gnss = p.copter.gnss
                assert gnss.valid_frames == sum(corrections.injected.values()), (
                    gnss.valid_frames,
                    corrections,
                )
                # a third-party rover on the base's stream: plain TCP, RTKLIB's tcpcli://
                port = p.agent.config.rtk.local_source.rsplit(":", 1)[1]
                out = tmp_path / "rover.rtcm3"
                rover = await str2str(f"tcpcli://127.0.0.1:{port}", out)
                try:
                    await eventually(lambda: len(frames_in(out)) >= 5, 20, "frames at str2str")
                finally:
                    await stop(rover)
    finally:
        await asyncio.to_thread(server.stop)
