"""NTRIP through the deployment's proxy: nginx runs deploy/nginx/ntrip.conf (a stream context, the
file docker-compose.yml mounts) in front of two replicas' casters, and the HTTP server block's
`/ntrip/` route. A rover on either door gets its base's corrections, whichever replica it lands
on (they reach every replica through Redis), and an NTRIP 1 rover goes on getting them after the
replica it was on is killed. The replicas refuse a connection that does not start with the
proxy's PROXY line, so the rovers' corrections also show that nginx sends it."""

from __future__ import annotations

import asyncio
import base64
import queue
import signal
from typing import Any

import pytest
from pygnssutils import GNSSNTRIPClient

from aerobase.ports import free_port
from assetlink.configfile import decrypt_config
from assetlink.link import Link
from protocol.rtcm import frame_ok, message_type
from tests.conftest import Tenant
from tests.polling import eventually
from tests.replicas import proxy, replicas
from tests.rtk import base_sending, frames_in, stop, str2str

pytestmark = pytest.mark.slow


async def test_rovers_get_corrections_through_the_proxy_and_across_a_replica_kill(
    database_url, api, superuser_email, tmp_path
):
    tenant = Tenant(api, superuser_email, "ntrip-proxy")
    base = tenant.create_asset("landing_base")
    cfg = decrypt_config(base64.b64decode(base["config_file"]), "asset-password-123")
    casters, listen = [free_port(), free_port()], free_port()
    settings = [  # as docker-compose.yml: the proxy names each rover in a PROXY line
        {"AEROBASE_NTRIP_PORT": str(port), "AEROBASE_NTRIP_PROXY_PROTOCOL": "true"}
        for port in casters
    ]
    user = f"{tenant.emails['viewer']}:{Tenant.PASSWORD}"
    with (
        replicas(database_url, tmp_path, settings=settings) as servers,
        proxy([port for port, _ in servers], tmp_path, ntrip=(listen, casters)) as url,
    ):
        # the base's daemon on the replica that stays: its corrections reach both through Redis
        link = Link(f"http://127.0.0.1:{servers[1][0]}", cfg.name, cfg.secret,
                    tmp_path / "base.db", agent="base_station", seed=5)  # fmt: skip
        await link.start()
        rovers: list[asyncio.subprocess.Process] = []
        v2: Any = None
        try:
            await link.wait_connected(20)
            async with base_sending(link):
                # two NTRIP 1 rovers through the stream proxy: round robin puts one on each
                files = [tmp_path / f"rover{i}.rtcm3" for i in range(2)]
                for out in files:
                    mount = f"ntrip://{user}@127.0.0.1:{listen}/{base['name']}"
                    rovers.append(await str2str(mount, out, "-r", "1000", "-s", "3000"))
                # and an NTRIP 2 rover on the HTTP port's /ntrip/, through the server block
                got: queue.Queue[Any] = queue.Queue()
                v2 = GNSSNTRIPClient(retries=0, timeout=5, verbosity=0)
                v2.run(server="127.0.0.1", port=int(url.rsplit(":", 1)[1]),
                       mountpoint=f"ntrip/{base['name']}", ntripuser=tenant.emails["viewer"],
                       ntrippassword=Tenant.PASSWORD, version="2.0", output=got)  # fmt: skip
                await eventually(
                    lambda: all(len(frames_in(f)) >= 8 for f in files) and got.qsize() >= 8,
                    within=30,
                    what="corrections at every rover through the proxy",
                )
                v2_frames = [got.get_nowait()[0] for _ in range(got.qsize())]

                # kill -9 the other replica: its rover reconnects through the proxy
                log = tmp_path / "nginx" / "error.log"  # nginx says where it sent each rover

                def sent_to_survivor() -> int:
                    return log.read_text().count(f"connected to 127.0.0.1:{casters[1]}\n")

                assert sent_to_survivor() == 1  # round robin: one rover on each replica
                servers[0][1].send_signal(signal.SIGKILL)
                servers[0][1].wait()
                before = [len(frames_in(f)) for f in files]
                await eventually(
                    lambda: all(
                        len(frames_in(f)) >= n + 8 for f, n in zip(files, before, strict=True)
                    ),
                    within=30,
                    what="corrections at both NTRIP 1 rovers after the kill",
                )
                assert sent_to_survivor() == 2  # the killed replica's rover, reconnected
        finally:
            for rover in rovers:
                await stop(rover)
            if v2 is not None:
                v2.stop()
            await link.stop()
    for f in files:
        frames = frames_in(f)
        assert all(frame_ok(x) for x in frames)
        assert {message_type(x) for x in frames} >= {1005, 1077, 1097}
        assert f.read_bytes()[0] == 0xD3  # nothing but RTCM3, from the first byte
    assert v2_frames and all(frame_ok(x) for x in v2_frames)
