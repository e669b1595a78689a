"""The deployment topology natively: nginx running deploy/nginx/aerobase.conf (the file
docker-compose.yml mounts) in front of two `aerobase server` replicas on one database and Redis.

What a proxy in front of replicas must get right: HTTP and both WebSockets pass through (the
Upgrade handshake, long-lived frames both ways), a replica's death is invisible to HTTP callers,
and a daemon's link reconnects through the proxy to the surviving replica with nothing lost.
"""

from __future__ import annotations

import asyncio
import base64
import json
import signal
import uuid

import httpx
import pytest
import websockets

from assetlink.configfile import decrypt_config
from assetlink.link import Link
from protocol.telemetry_payloads import Position, UavTelemetry
from server.realtime.asset_session import PRESENCE_TTL_S
from tests.conftest import Tenant
from tests.metrics import value
from tests.polling import eventually
from tests.replicas import proxy, replicas

pytestmark = pytest.mark.slow


def _subscribe(asset_id: str) -> str:
    return json.dumps(
        {
            "v": 1,
            "type": "subscribe",
            "id": str(uuid.uuid4()),
            "seq": 0,
            "ts": 0,
            "payload": {"asset_ids": [asset_id]},
        }
    )


def _sample(i: int) -> UavTelemetry:
    return UavTelemetry(position=Position(lat=41.0, lon=-8.6, alt_msl_m=120, alt_rel_m=float(i)))


async def _stored_seqs(url: str, tenant: Tenant, asset_id: str) -> list[float]:
    async with httpx.AsyncClient(base_url=url) as c:
        r = await c.get(
            f"/api/v1/assets/{asset_id}/telemetry",
            params={"fields": "position.alt_rel_m", "limit": 10_000},
            headers=tenant.h("viewer"),
        )
    r.raise_for_status()
    return sorted(row["position.alt_rel_m"] for row in r.json())


async def test_http_and_both_sockets_pass_the_proxy_and_survive_a_replica_kill(
    database_url, api, superuser_email, tmp_path
):
    tenant = Tenant(api, superuser_email, "proxy")
    asset = tenant.create_asset("uav")
    cfg = decrypt_config(base64.b64decode(asset["config_file"]), "asset-password-123")
    with replicas(database_url, tmp_path) as servers:
        with proxy([port for port, _ in servers], tmp_path) as url:
            link = Link(url, cfg.name, cfg.secret, tmp_path / "link.db", seed=3)
            await link.start()
            try:
                await link.wait_connected(20)
                ws = url.replace("http", "ws") + f"/ws/operator?token={tenant.tokens['viewer']}"
                async with websockets.connect(ws) as op:
                    await op.send(_subscribe(asset["id"]))

                    # the subscription goes through Redis when the two sockets sit on different
                    # replicas: keep sending until a sample arrives at the operator
                    sent = 0

                    async def arrived() -> bool:
                        nonlocal sent
                        await link.send_telemetry(_sample(sent))
                        sent += 1
                        try:
                            async with asyncio.timeout(0.2):
                                msg = json.loads(await op.recv())
                        except TimeoutError:
                            return False
                        return msg["type"] == "telemetry"

                    await eventually(arrived, 20, "telemetry at the operator through the proxy")

                # kill -9 one replica: HTTP through the proxy keeps answering
                servers[0][1].send_signal(signal.SIGKILL)
                servers[0][1].wait()
                async with httpx.AsyncClient(base_url=url) as c:
                    codes = [(await c.get("/api/health")).status_code for _ in range(20)]
                assert codes == [200] * 20

                # the link (on either replica before) is connected afterwards and what it sends
                # after the kill is stored, as is everything before: nothing lost, nothing twice
                for i in range(sent, sent + 20):
                    await link.send_telemetry(_sample(i))
                total = sent + 20
                # a dead replica cannot release the asset's presence claim: the surviving one
                # admits the link once that claim's time to live has run out
                await link.wait_connected(PRESENCE_TTL_S + 30)
                assert await link.flush(30), "the outbox did not drain through the proxy"
                assert await _stored_seqs(url, tenant, asset["id"]) == [
                    float(i) for i in range(total)
                ]
            finally:
                await link.stop()


async def test_sigterm_closes_sockets_for_an_immediate_reconnect_and_exits_within_10_s(
    database_url, api, superuser_email, tmp_path
):
    """A replica stopped cleanly (SIGTERM, as an orchestrator does) tells its sockets to come back
    at once (1012), gives up its assets' presence and exits: the link is on the other replica
    well before a killed replica's presence key would have lapsed."""
    tenant = Tenant(api, superuser_email, "sigterm")
    asset = tenant.create_asset("uav")
    cfg = decrypt_config(base64.b64decode(asset["config_file"]), "asset-password-123")
    with replicas(database_url, tmp_path) as servers:
        with proxy([port for port, _ in servers], tmp_path) as url:
            link = Link(url, cfg.name, cfg.secret, tmp_path / "link.db", seed=4)
            await link.start()
            try:
                await link.wait_connected(20)
                async with httpx.AsyncClient() as c:
                    counts = [
                        value(
                            (await c.get(f"http://127.0.0.1:{port}/metrics")).text,
                            "aerobase_connected_assets",
                        )
                        for port, _ in servers
                    ]
                holder = servers[counts.index(1.0)][1]
                reconnects = link.stats.reconnects
                holder.send_signal(signal.SIGTERM)
                await asyncio.to_thread(holder.wait, 10)
                # uvicorn shuts down, then re-raises the signal: 143 to the orchestrator
                assert holder.returncode == -signal.SIGTERM
                log = (tmp_path / "servers.log").read_text()
                assert f"Finished server process [{holder.pid}]" in log
                await eventually(
                    lambda: link.connected and link.stats.reconnects > reconnects,
                    PRESENCE_TTL_S,
                    "the link back on the surviving replica before a lapsed presence would allow",
                )
            finally:
                await link.stop()
