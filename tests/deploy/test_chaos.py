"""A replica dies mid-run: kill -9 the server process that holds a flying run's lease, behind the
proxy, with a second replica beside it; the run completes on the survivor.

The native topology of docker-compose.yml: nginx (deploy/nginx/aerobase.conf) in front of two
`aerobase server` processes on their own PostgreSQL database and Redis; the simulated world, both
daemons and operators' sockets connect through the proxy, as they would in a deployment.
"""

from __future__ import annotations

import asyncio
import json
import math
import re
import signal
import sqlite3
import time
import uuid
from collections import Counter
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import httpx
import pytest
import websockets
from sqlalchemy import text
from sqlalchemy.ext.asyncio import create_async_engine

from tests.conftest import Tenant
from tests.deploy.conftest import ROOT_EMAIL
from tests.e2e.harness import FINAL, platform
from tests.e2e.test_autonomous_run import WHOLE_SEQUENCE
from tests.metrics import value
from tests.polling import eventually
from tests.replicas import proxy, replicas

pytestmark = pytest.mark.slow

MOTION = {"open", "close", "open_panels", "close_panels", "lift_up", "lift_down", "start_mission"}


async def _lease_owner(url: str, run_id: str) -> str | None:
    engine = create_async_engine(url)
    try:
        async with engine.connect() as conn:
            row = await conn.execute(
                text("SELECT lease_owner FROM runs WHERE id = :id"), {"id": uuid.UUID(run_id)}
            )
            return row.scalar_one_or_none()
    finally:
        await engine.dispose()


async def _telemetry_seqs(url: str, asset_id: str) -> list[int]:
    """The sequence numbers of an asset's stored telemetry rows, in time order."""
    engine = create_async_engine(url)
    try:
        async with engine.connect() as conn:
            rows = await conn.execute(
                text("SELECT seq FROM telemetry WHERE asset_id = :id ORDER BY ts, seq"),
                {"id": uuid.UUID(asset_id)},
            )
            return [seq for (seq,) in rows]
    finally:
        await engine.dispose()


class Operator:
    """An operator's socket through the proxy following the run's UAV; when it is closed it
    reconnects through the proxy and subscribes again at once (what the web client does), and
    keeps every `run_progress` of the run with the wall time it arrived."""

    def __init__(self, proxy_url: str, token: str, uav_id: str, run_id: str) -> None:
        self.url = proxy_url.replace("http", "ws", 1) + f"/ws/operator?token={token}"
        self.uav_id, self.run_id = uav_id, run_id
        self.progress: list[tuple[float, dict[str, Any]]] = []
        self.closes = 0
        self.ws: Any = None

    async def connect(self) -> None:
        self.ws = await websockets.connect(self.url)
        subscribe = {"v": 1, "type": "subscribe", "id": str(uuid.uuid4()), "seq": 0, "ts": 0}
        await self.ws.send(json.dumps({**subscribe, "payload": {"asset_ids": [self.uav_id]}}))

    async def follow(self) -> None:
        """Read until the run's final progress, reconnecting whenever the socket closes."""
        while True:
            try:
                async for raw in self.ws:
                    msg = json.loads(raw)
                    payload = msg.get("payload") or {}
                    if msg["type"] == "run_progress" and payload["run_id"] == self.run_id:
                        self.progress.append((time.time(), payload))
                        if payload["final"]:
                            return
            except websockets.ConnectionClosed:
                pass
            self.closes += 1
            await eventually(self._reconnect, 30, "an operator socket through the proxy")

    async def _reconnect(self) -> bool:
        try:
            await self.connect()
        except (OSError, websockets.InvalidHandshake):
            return False
        return True

    def states_after(self, wall: float) -> list[str]:
        """The run's states announced after `wall`, repeats of one state once."""
        states: list[str] = []
        for at, payload in self.progress:
            if at > wall and (not states or states[-1] != payload["state"]):
                states.append(payload["state"])
        return states


async def _operators_on(ports: dict[str, int]) -> dict[str, float]:
    async with httpx.AsyncClient() as c:
        return {
            node: value(
                (await c.get(f"http://127.0.0.1:{port}/metrics")).text,
                "aerobase_connected_operators",
            )
            for node, port in ports.items()
        }


async def _operators_on_each_replica(
    url: str, token: str, run_id: str, uav_id: str, ports: dict[str, int]
) -> dict[str, Operator]:
    """Operator sockets opened through the proxy until one is on each replica (which replica
    took a socket is read from the replicas' own /metrics)."""
    placed: dict[str, Operator] = {}
    extra: list[Operator] = []
    for _ in range(6):
        before = await _operators_on(ports)
        op = Operator(url, token, uav_id, run_id)
        await op.connect()

        async def landed(before: dict[str, float] = before) -> str | None:
            now = await _operators_on(ports)
            return next((n for n in ports if now[n] > before[n]), None)

        node = await eventually(landed, 10, "the operator socket to be counted by a replica")
        if node in placed:
            extra.append(op)
        else:
            placed[node] = op
        if len(placed) == len(ports):
            break
    for op in extra:
        await op.ws.close()
    assert len(placed) == len(ports), f"the proxy put every operator socket on {set(placed)}"
    return placed


def _wall(iso: str) -> float:
    at = datetime.fromisoformat(iso)
    return (at if at.tzinfo else at.replace(tzinfo=UTC)).timestamp()


def _ledger(state_file: Path) -> Counter[str]:
    """The commands a daemon executed, by name, from its link's command ledger."""
    with sqlite3.connect(state_file) as db:
        return Counter(name for (name,) in db.execute("SELECT name FROM commands"))


async def test_killing_the_lease_holder_mid_flight_the_run_completes_on_the_other_replica(
    own_database, tmp_path
):
    with replicas(own_database, tmp_path) as servers:
        nodes = {}
        async with httpx.AsyncClient() as c:
            for port, proc in servers:
                health = (await c.get(f"http://127.0.0.1:{port}/api/health")).json()
                nodes[f"runs-{health['node']}"] = (port, proc)
        with proxy([port for port, _ in servers], tmp_path) as url:
            with httpx.Client(base_url=url, timeout=30) as api:
                tenant = Tenant(api, ROOT_EMAIL, "chaos")
                async with platform(url, tenant, tmp_path, precland={}, speed=2.5) as p:
                    run_id = await p.start_run()
                    await p.wait_state(run_id, ("flying",), 90)
                    await eventually(
                        lambda: p.world.base.pad_mass_g == 0, 60, "the UAV to take off"
                    )
                    holder = await _lease_owner(own_database, run_id)
                    assert holder in nodes, (holder, nodes)
                    operators = await _operators_on_each_replica(
                        url,
                        tenant.tokens["viewer"],
                        run_id,
                        p.ids["uav_id"],
                        {node: port for node, (port, _) in nodes.items()},
                    )
                    following = {n: asyncio.create_task(op.follow()) for n, op in operators.items()}
                    port, proc = nodes.pop(holder)
                    killed_at = time.time()
                    proc.send_signal(signal.SIGKILL)
                    proc.wait()
                    (survivor,) = nodes

                    body = await p.wait_state(run_id, FINAL, 240)
                    assert body["state"] == "completed", (
                        body["reason"],
                        [(t["to_state"], t["reason"]) for t in body["timeline"]],
                        {"pad_distance_m": round(p.copter.pad_distance(), 3)},
                    )
                    steps = [
                        t["to_state"] for t in body["timeline"] if t["cause"] != "lease_takeover"
                    ]
                    assert steps.count("flying") == 1  # resumed where it stood
                    takeovers = [t for t in body["timeline"] if t["cause"] == "lease_takeover"]
                    assert len(takeovers) == 1 and survivor in takeovers[0]["reason"], takeovers
                    taken_after = _wall(takeovers[0]["at"]) - killed_at
                    assert taken_after <= 10, f"taken over {taken_after:.1f} s after the kill"
                    assert await _lease_owner(own_database, run_id) in (survivor, None)

                    # both operators (the one whose replica died reconnected through the proxy)
                    # received every step the run took after the kill, up to its completion
                    await asyncio.wait_for(asyncio.gather(*following.values()), 30)
                    after_kill = [
                        t["to_state"]
                        for t in body["timeline"]
                        if _wall(t["at"]) > killed_at and t["from_state"] != t["to_state"]
                    ]
                    assert after_kill[-1] == "completed", after_kill
                    assert operators[holder].closes >= 1
                    assert operators[survivor].closes == 0
                    for node, op in operators.items():
                        seen = [s for s in op.states_after(killed_at) if s != "flying"]
                        assert seen == after_kill, (node, seen, after_kill)

                    # every durable message of the agent was acked (acks follow storage)
                    uav_link = p.agent.link
                    assert await uav_link.flush(60)
                    assert uav_link.stats.dropped == 0
                    # the flight's telemetry rows are complete: every sample the agent queued is
                    # stored, each sequence number once (a replay of the dead replica's unacked
                    # tail is absorbed by the store's (asset, seq, ts) key). The agent reports
                    # telemetry while its autopilot answers (5 Hz): silence the simulated
                    # autopilot so the count holds still, rather than hoping for a quiet instant
                    # between two samples (under load there was none in 30 s).
                    p.copter.faults.mute_until = math.inf
                    await eventually(
                        lambda: not p.agent.autopilot.link_up,
                        30,
                        "the agent to see its autopilot gone",
                    )
                    uav_id = p.ids["uav_id"]

                    async def all_stored() -> bool:
                        before = uav_link.stats
                        seqs = await _telemetry_seqs(own_database, uav_id)
                        after = uav_link.stats
                        assert len(seqs) == len(set(seqs)), Counter(seqs).most_common(3)
                        assert seqs == sorted(seqs), "stored out of the agent's order"
                        return (
                            before.queued == after.queued == 0
                            and before.telemetry_queued == after.telemetry_queued == len(seqs)
                        )

                    await eventually(all_stored, 30, "every queued telemetry sample stored")
                # every log line of a run carries its id, every request line the proxy's request id
                lines = [
                    json.loads(line)
                    for line in (tmp_path / "servers.log").read_text().splitlines()
                    if line.startswith("{")
                ]
                moves = [x for x in lines if x.get("run_id") == run_id and "->" in x["event"]]
                assert len(moves) >= len(WHOLE_SEQUENCE), moves
                served = [x for x in lines if x.get("logger") == "aerobase.access"]
                assert served and all(
                    re.fullmatch(r"[0-9a-f]{32}", x["request_id"]) for x in served
                )
                # each motion command ran once on its daemon, whichever replica delivered it
                for ledger in (_ledger(tmp_path / "base.db"), _ledger(tmp_path / "agent.db")):
                    twice = {n: c for n, c in ledger.items() if n in MOTION and c > 1}
                    assert not twice, ledger
