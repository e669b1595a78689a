"""The server's telemetry hot path in one process, without the network: CPU per message by stage.

    python bench/hotpath.py [--assets 100] [--rate 10] [--seconds 10] [--operators 2]
                            [--profile] [--json]

The real app (`create_app`: its database, migrations, ingest, broker, hub) runs its real sessions
(`AssetSession`, `OperatorSession`) over real `NativeSocket`s whose transports are in-memory:
what an asset "sends" is a masked WebSocket frame handed to `data_received`, what the server
writes is counted and dropped. N assets each send one telemetry envelope (the benchmark's own,
bench/_load.py) every 1/R s, paced by the event loop as the network would deliver them. What
this leaves out is the kernel's share of a real socket (recv, send, epoll), which
bench/telemetry.py measures with the rest; what it adds is repeatability: no load generator,
no Mosquitto, no other process on the server's core, so its figures move little on a busy
machine. It prints the process's CPU per message (all threads, and per thread) and, with
--profile, where the
main thread spends it (yappi, CPU time by function; the dev extra installs it).
"""

from __future__ import annotations

import argparse
import asyncio
import json
import os
import resource
import sys
import tempfile
import time
import uuid
from datetime import UTC, datetime, timedelta
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from bench._load import Payloads
from server.realtime import rfc6455 as ws

TICK_S = 0.002


class NullTransport:
    """A transport that takes every write at once (and counts it)."""

    def __init__(self) -> None:
        self.writes = 0
        self.bytes = 0
        self.closed = False

    def write(self, data: bytes) -> None:
        self.writes += 1
        self.bytes += len(data)

    def is_closing(self) -> bool:
        return self.closed

    def close(self) -> None:
        self.closed = True

    abort = close

    def pause_reading(self) -> None:
        """Nothing to pause: the harness hands frames in itself."""

    def resume_reading(self) -> None:
        """See `pause_reading`."""

    def get_extra_info(self, name: str, default: Any = None) -> Any:
        return default


def masked(text: str) -> bytes:
    """`text` as a client's masked text frame."""
    data = text.encode()
    mask = os.urandom(4)
    n = len(data)
    head = bytes([0x81, 0x80 | n]) if n < 126 else bytes([0x81, 0xFE]) + n.to_bytes(2, "big")
    return head + mask + ws._unmask(data, mask)


def thread_cpu() -> dict[str, float]:
    """CPU seconds of each thread of this process, by name (from /proc)."""
    out: dict[str, float] = {}
    tick = os.sysconf("SC_CLK_TCK")
    for task in Path("/proc/self/task").iterdir():
        try:
            name = (task / "comm").read_text().strip()
            fields = (task / "stat").read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        key = "main" if task.name == str(os.getpid()) else name
        out[key] = out.get(key, 0.0) + (int(fields[11]) + int(fields[12])) / tick
    return out


def cpu_s() -> float:
    """This process's CPU seconds (every thread)."""
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime


async def run(args: argparse.Namespace) -> dict[str, Any]:
    """Set up the app, connect the sessions, drive the load, measure."""
    from server.app import create_app
    from server.assets.models import Asset
    from server.auth.models import AuthSession
    from server.config import Settings
    from server.deps import services_of
    from server.kit.principal import Principal, Role
    from server.organizations.models import Organization
    from server.realtime.asset_session import AssetSession
    from server.realtime.native_socket import Limits, NativeSocket
    from server.realtime.operator_session import OperatorSession

    folder = tempfile.mkdtemp(prefix="aerobase-hotpath-")
    url = os.environ.get("DATABASE_URL") or f"sqlite+aiosqlite:///{folder}/hotpath.db"
    settings = Settings(database_url=url, run_engine=False, environment="development")
    app = create_app(settings)
    async with app.router.lifespan_context(app):
        services = services_of(app)
        org = uuid.uuid4()
        assets = [uuid.uuid4() for _ in range(args.assets)]
        # the login sessions the sockets belong to (the hub ends sockets of unknown sessions)
        asset_sessions = [uuid.uuid4() for _ in assets]
        user_sessions = [uuid.uuid4() for _ in range(args.operators)]
        async with services.sessionmaker() as db:
            db.add(Organization(id=org, name=f"hotpath-{org.hex[:8]}"))
            await db.flush()
            for a in assets:
                db.add(
                    Asset(
                        id=a, organization_id=org, name=f"hp-{a.hex}", kind="uav", secret_hash="-"
                    )
                )
            await db.flush()
            expires = datetime.now(UTC) + timedelta(hours=1)
            for sid, kind, a in [
                (s, "asset", a) for s, a in zip(asset_sessions, assets, strict=True)
            ] + [(s, "user", None) for s in user_sessions]:
                db.add(
                    AuthSession(
                        id=sid,
                        token_hash=sid.hex,
                        principal_kind=kind,
                        asset_id=a,
                        organization_id=org,
                        expires_at=expires,
                        idle_timeout_s=3600,
                    )
                )
            await db.commit()
        limits = Limits(ping_interval_s=None, ping_timeout_s=None)
        tasks = []
        operators = []
        for session_id in user_sessions:
            transport = NullTransport()
            sock = NativeSocket(transport, limits)  # type: ignore[arg-type]
            user = Principal("user", session_id, org, Role.viewer, uuid.uuid4())
            tasks.append(asyncio.create_task(OperatorSession(services, sock, user).serve()))
            await sock.accept()
            ids = [str(a) for a in assets]
            sock.data_received(
                masked(json.dumps({"type": "subscribe", "payload": {"asset_ids": ids}}))
            )
            operators.append((sock, transport))
        socks = []
        for a, session_id in zip(assets, asset_sessions, strict=True):
            transport = NullTransport()
            sock = NativeSocket(transport, limits)  # type: ignore[arg-type]
            me = Principal("asset", session_id, org, asset_id=a)
            tasks.append(asyncio.create_task(AssetSession(services, sock, me, a, org).serve()))
            await sock.accept()
            sock.data_received(
                masked(
                    json.dumps(
                        {
                            "v": 1,
                            "type": "hello",
                            "id": str(uuid.uuid4()),
                            "seq": 0,
                            "ts": int(time.time() * 1000),
                            "payload": {
                                "stream": str(uuid.uuid4()),
                                "agent": "asset_agent",
                                "version": "hotpath",
                            },
                        }
                    )
                )
            )
            socks.append((sock, transport))
        # every session past its hello (its socket delivers to it) and its first command sweep
        while any(sock._handler is None for sock, _ in socks):  # noqa: ASYNC110
            await asyncio.sleep(0.01)
        await asyncio.sleep(1.0)
        payloads = Payloads(args.assets)
        period = 1.0 / args.rate
        loop = asyncio.get_running_loop()
        total = int(args.seconds * args.rate) * args.assets
        frames = [
            [masked(payloads.text(i, k + 1)) for k in range(int(args.seconds * args.rate))]
            for i in range(args.assets)
        ]
        if args.profile:
            import yappi  # the dev extra; CPU time per function, every thread, greenlets too

            yappi.set_clock_type("cpu")
            yappi.start(builtins=True)
        print(f"measuring {total} messages", file=sys.stderr, flush=True)
        start_cpu, start, threads = cpu_s(), loop.time(), thread_cpu()
        # what is due goes in every TICK_S, as epoll hands a server what arrived meanwhile (one
        # timer per tick, not per message: the harness's own cost stays out of the figures)
        due = sorted(
            (k * period + i * period / args.assets, i, k)
            for i in range(args.assets)
            for k in range(int(args.seconds * args.rate))
        )
        next_tick = start
        for at, i, k in due:
            if start + at > next_tick:
                next_tick += TICK_S
                delay = next_tick - loop.time()
                if delay > 0:
                    await asyncio.sleep(delay)
            socks[i][0].data_received(frames[i][k])
        waited = loop.time()
        while services.ingest.stored < total:
            if loop.time() - waited > 30:
                c = services.hub.counters
                raise RuntimeError(
                    f"stored {services.ingest.stored} of {total} (received {c.received}, "
                    f"malformed {c.malformed}, duplicates {c.duplicates}; "
                    f"socket states {sorted({(x.state, x.close_code) for x, _ in socks})})"
                )
            await asyncio.sleep(0.01)
        await asyncio.sleep(0.3)  # the last acks (ws_ack_interval_s)
        if args.profile:
            yappi.stop()
            stats = yappi.get_func_stats()
            stats.sort("tsub")
            print("functions by own CPU time (yappi; profiling slows everything ~3x):")
            stats.print_all(
                columns={0: ("name", 90), 1: ("ncall", 9), 2: ("tsub", 8), 3: ("ttot", 8)},
                out=sys.stdout,
            )
        used, wall = cpu_s() - start_cpu, loop.time() - start
        after = thread_cpu()
        by_thread = {k: round(v - threads.get(k, 0.0), 2) for k, v in after.items()}
        delivered = services.hub.counters.sent_to_operators
        result = {
            "messages": total,
            "cpu_s": round(used, 3),
            "wall_s": round(wall, 2),
            "cpu_us_per_message": round(1e6 * used / total, 1),
            "delivered_to_operators": delivered,
            "operator_writes": sum(t.writes for _, t in operators),
            "asset_writes": sum(t.writes for _, t in socks),
            "stored": services.ingest.stored,
            "cpu_s_by_thread": {k: v for k, v in by_thread.items() if v},
        }
        for sock, _ in socks + operators:
            sock.connection_lost(None)
        for t in tasks:
            t.cancel()
        await asyncio.gather(*tasks, return_exceptions=True)
    return result


def main(argv: list[str] | None = None) -> int:
    """Run and print the figures."""
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--assets", type=int, default=100)
    p.add_argument("--rate", type=float, default=10.0)
    p.add_argument("--seconds", type=float, default=10.0)
    p.add_argument("--operators", type=int, default=2)
    p.add_argument("--profile", action="store_true")
    p.add_argument("--json", action="store_true")
    args = p.parse_args(argv)
    import uvloop

    result = uvloop.run(run(args))
    print(json.dumps(result) if args.json else "\n".join(f"{k}: {v}" for k, v in result.items()))
    return 0


if __name__ == "__main__":
    sys.exit(main())
