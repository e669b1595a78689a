"""The RTK chain through the real server: simulated GNSS receiver -> base-station RTCM reader ->
base link -> server -> (a) the UAV bound to that base, (b) a third-party NTRIP client on the caster."""

from __future__ import annotations

import base64
import queue

import httpx
import pytest
from pygnssutils import GNSSNTRIPClient

from assetlink.configfile import decrypt_config
from assetlink.link import Link
from protocol.rtcm import frame_ok, message_type
from server.deps import services_of
from tests.conftest import LiveServer, Tenant
from tests.metrics import value
from tests.polling import eventually
from tests.rtk import base_sending, frames_in, stop, str2str

pytestmark = pytest.mark.slow  # whole processes end to end: not in the fast lane


def _cfg(asset: dict):  # type: ignore[no-untyped-def]
    return decrypt_config(base64.b64decode(asset["config_file"]), "asset-password-123")


def rovers(server: LiveServer) -> tuple[float, float]:
    """The server's NTRIP clients on /metrics: (version 1, version 2)."""
    text = httpx.get(f"{server.url}/metrics", timeout=10).text
    count = "aerobase_ntrip_clients"
    return value(text, count, version="1"), value(text, count, version="2")


async def test_corrections_reach_the_bound_uav_and_an_ntrip_client(
    live_server, tenant: Tenant, tmp_path
):
    base = tenant.create_asset("landing_base")
    uav = tenant.create_asset("uav", base_id=base["id"])
    bcfg, ucfg = _cfg(base), _cfg(uav)
    base_link = Link(
        live_server.url, bcfg.name, bcfg.secret, tmp_path / "base.db", agent="base_station", seed=1
    )
    uav_link = Link(live_server.url, ucfg.name, ucfg.secret, tmp_path / "uav.db", seed=2)
    at_uav: list[bytes] = []
    uav_link.on_rtcm(at_uav.append)
    await base_link.start()
    await uav_link.start()
    ntrip_out: queue.Queue = queue.Queue()
    client = None
    try:
        await base_link.wait_connected(15)
        await uav_link.wait_connected(15)
        async with base_sending(base_link):
            await eventually(lambda: len(at_uav) >= 8, what="corrections at the UAV")
            before = rovers(live_server)
            client = GNSSNTRIPClient(retries=0, timeout=5, verbosity=0)
            client.run(
                server="127.0.0.1",
                port=live_server.port,
                mountpoint=f"ntrip/{base['name']}",
                ntripuser=tenant.emails["viewer"],
                ntrippassword=Tenant.PASSWORD,
                version="2.0",
                output=ntrip_out,
            )
            await eventually(lambda: ntrip_out.qsize() >= 8, what="corrections at the NTRIP client")
            # and RTKLIB's str2str, an NTRIP 1 client, on the caster's own port
            caster = services_of(live_server.app).ntrip
            assert caster is not None
            user = f"{tenant.emails['viewer']}:{Tenant.PASSWORD}"  # str2str splits at the last @
            mount = f"ntrip://{user}@127.0.0.1:{caster.port}/{base['name']}"
            rover = await str2str(mount, tmp_path / "str2str.rtcm3")
            try:
                await eventually(
                    lambda: len(frames_in(tmp_path / "str2str.rtcm3")) >= 8,
                    what="corrections at str2str",
                )
                # /metrics counts both rovers, by version (over what the process had before)
                assert rovers(live_server) == (before[0] + 1, before[1] + 1)
            finally:
                await stop(rover)
            client.stop()
            await eventually(lambda: rovers(live_server) == before, what="the rovers uncounted")
    finally:
        if client is not None:
            client.stop()
        await uav_link.stop()
        await base_link.stop()
    assert all(frame_ok(f) for f in at_uav)
    assert {message_type(f) for f in at_uav} >= {1005, 1077, 1097}
    pulled = [ntrip_out.get_nowait()[0] for _ in range(ntrip_out.qsize())]
    assert pulled and all(frame_ok(f) for f in pulled)
    assert {message_type(f) for f in frames_in(tmp_path / "str2str.rtcm3")} >= {1005, 1077}
