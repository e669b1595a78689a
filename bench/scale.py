"""Telemetry through the proxy in front of one, then two `aerobase server` replicas, in one run.

    DATABASE_URL=postgresql+asyncpg://... python bench/scale.py [--assets 300] [--rate 10]
        [--seconds 15] [--operators 1] [--warmup 3] [--repeat 3] [--redis-url redis://...] [--json]

The deployment's topology (tests/deploy, docker-compose.yml): nginx running deploy/nginx/aerobase.conf
in front of N replicas on one PostgreSQL database and Redis. The load is bench/telemetry_load.py's
(bench/_aerobase.py `run_ours`: N simulated UAVs over /ws/asset, operators over /ws/operator, every
message timed from its send to each operator), here aimed at the proxy. The two topologies
alternate (1, 2, 1, 2, ...) `--repeat` times on fresh processes; the figures are medians. CPU is
every server process's plus nginx's, start of the load to drained, per 1,000 acked messages (Redis
and PostgreSQL are shared with the rest of the machine and not counted). The machine's CPU pressure
(/proc/pressure/cpu) is printed beside the figures: on a small shared machine the generator, the
proxy and the replicas compete for the same cores, which bounds what a second replica can add.
Exits 0 with the figures; non-zero only when it could not run.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
import uuid
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from bench._aerobase import SUPER_PASSWORD, raise_fd_limit, run_ours, server_env, set_up
from bench._load import Payloads, process_cpu
from tests.replicas import proxy, replicas

ROOT = Path(__file__).resolve().parents[1]
FIGURES = {
    "ingest_rate_msg_s": ("ingest rate, acked (msg/s)", lambda r: r["ingest_rate_msg_s"]),
    "delivered_rate_msg_s": ("delivered to operators (msg/s)", lambda r: r["delivered_rate_msg_s"]),
    "p50_ms": ("latency p50 (ms)", lambda r: r["latency_ms"]["p50"]),
    "p99_ms": ("latency p99 (ms)", lambda r: r["latency_ms"]["p99"]),
    "cpu_s_per_1000": (
        "CPU s per 1,000 msgs (replicas + nginx)",
        lambda r: r["cpu_s_per_1000_all"],
    ),
    "lost": ("lost (ingest + delivery)", lambda r: r["lost_ingest"] + r["lost_delivery"]),
    "send_lag_p99_ms": ("generator send lag p99 (ms)", lambda r: r["generator_send_lag_ms_p99"]),
}


def progress(text: str) -> None:
    """A progress line on stderr."""
    print(f"[{time.strftime('%H:%M:%S')}] {text}", file=sys.stderr, flush=True)


def parse(argv: list[str] | None) -> argparse.Namespace:
    """Command-line flags."""
    p = argparse.ArgumentParser(prog="bench/scale.py", description=__doc__.split("\n\n")[0])
    p.add_argument("--assets", type=int, default=300)
    p.add_argument("--rate", type=float, default=10.0, help="messages a second per UAV")
    p.add_argument("--seconds", type=float, default=15.0, help="measured seconds per run")
    p.add_argument("--warmup", type=float, default=3.0)
    p.add_argument("--operators", type=int, default=1)
    p.add_argument("--repeat", type=int, default=3, help="runs of each topology (medians)")
    p.add_argument("--redis-url", default="redis://127.0.0.1:6379/0")
    p.add_argument("--json", action="store_true", help="print the result as JSON")
    return p.parse_args(argv)


def _family(pid: int) -> list[int]:
    """`pid` and its children (nginx's workers)."""
    try:
        tasks = Path(f"/proc/{pid}/task").iterdir()
        kids = [int(k) for t in tasks for k in (t / "children").read_text().split()]
    except OSError:
        kids = []
    return [pid, *kids]


def cpu_s(pids: list[int]) -> float:
    """CPU seconds used so far by these processes and their children."""
    return sum(process_cpu(p) or 0.0 for pid in pids for p in _family(pid))


def pressure() -> str:
    """The machine's CPU pressure line (how busy the shared machine was)."""
    try:
        return Path("/proc/pressure/cpu").read_text().splitlines()[0]
    except (OSError, IndexError):
        return "n/a"


def prepare(database_url: str) -> str:
    """Migrate the database and create the superuser the set-up logs in as; returns its e-mail."""
    env = server_env(database_url, 0)
    root = f"scale-root-{uuid.uuid4().hex[:8]}@bench.test"
    cli = [sys.executable, "-m", "aerobase.cli", "admin"]
    for args in (
        ["migrate"],
        ["create-superuser", "--email", root, "--password", SUPER_PASSWORD],
    ):
        done = subprocess.run(
            [*cli, *args], env=env, cwd=ROOT, capture_output=True, text=True, timeout=120
        )
        if done.returncode != 0:
            raise RuntimeError(f"aerobase admin {args[0]} failed: {done.stderr.strip()[-500:]}")
    return root


async def one_run(
    args: argparse.Namespace,
    database_url: str,
    root: str,
    count: int,
    folder: Path,
    payloads: Payloads,
) -> dict[str, Any]:
    """The load through nginx in front of `count` fresh replicas; the figures of the run."""
    env = server_env(database_url, 0)
    settings = {k: v for k, v in env.items() if k.startswith("AEROBASE_") and k != "AEROBASE_PORT"}
    settings |= {"REDIS_URL": args.redis_url, "AEROBASE_MIGRATE_ON_START": "false"}
    with (
        replicas(database_url, folder, count, settings=settings) as servers,
        proxy([port for port, _ in servers], folder) as url,
    ):
        nginx = int((folder / "nginx" / "nginx.pid").read_text())
        pids = [proc.pid for _, proc in servers] + [nginx]
        fleet = await set_up(url, root, args.assets, args.operators, progress)
        progress(f"{count} replica(s) behind nginx at {url}: {args.assets} x {args.rate:g} Hz")
        before = cpu_s(pids)
        result = await run_ours(
            url,
            servers[0][1].pid,
            fleet,
            payloads,
            args.rate,
            args.warmup,
            args.seconds,
            progress,
        )
        used = cpu_s(pids) - before
    result["replicas"] = count
    result["cpu_s_all"] = round(used, 2)
    result["cpu_s_per_1000_all"] = (
        round(used / result["acked"] * 1000, 4) if result["acked"] else None
    )
    result["pressure"] = pressure()
    return result


def medians(runs: list[dict[str, Any]]) -> dict[str, float | None]:
    """The median of each figure over runs."""
    out: dict[str, float | None] = {}
    for key, (_, get) in FIGURES.items():
        values = [v for v in (get(r) for r in runs) if v is not None]
        out[key] = round(statistics.median(values), 3) if values else None
    return out


async def bench(args: argparse.Namespace) -> dict[str, Any]:
    """Both topologies, alternating, `--repeat` times each."""
    database_url = os.environ.get("DATABASE_URL", "")
    if not database_url.startswith("postgresql"):
        raise RuntimeError("set DATABASE_URL to a PostgreSQL database of the benchmark's own")
    raise_fd_limit()
    root = prepare(database_url)
    payloads = Payloads(args.assets)
    runs: dict[int, list[dict[str, Any]]] = {1: [], 2: []}
    tmp = tempfile.mkdtemp(prefix="aerobase-scale-")
    try:
        for k in range(args.repeat):
            for count in (1, 2):
                progress(f"run {k + 1}/{args.repeat}, {count} replica(s); {pressure()}")
                folder = Path(tempfile.mkdtemp(prefix=f"run-{k}-{count}-", dir=tmp))
                runs[count].append(await one_run(args, database_url, root, count, folder, payloads))
    except BaseException:
        progress(f"the servers' and nginx's logs are kept in {tmp}")
        raise
    shutil.rmtree(tmp, ignore_errors=True)
    one, two = medians(runs[1]), medians(runs[2])
    ratio = {
        key: None if one[key] in (None, 0) or two[key] is None else round(two[key] / one[key], 2)
        for key in FIGURES
        if key != "lost"
    }
    return {
        "benchmark": "scale",
        "assets": args.assets,
        "rate_hz": args.rate,
        "seconds": args.seconds,
        "operators": args.operators,
        "repeat": args.repeat,
        "cores": os.cpu_count(),
        "median": {"1": one, "2": two},
        "ratio_2_to_1": ratio,
        "runs": runs,
    }


def report(res: dict[str, Any]) -> str:
    """The medians and the ratio as a table."""
    one, two, ratio = res["median"]["1"], res["median"]["2"], res["ratio_2_to_1"]
    lines = [
        f"{res['assets']} UAVs x {res['rate_hz']:g} Hz, {res['operators']} operator(s), "
        f"{res['seconds']:g} s measured, medians of {res['repeat']} runs each, {res['cores']} cores",
        f"{'':44} {'1 replica':>12} {'2 replicas':>12} {'2 / 1':>8}",
    ]
    for key, (label, _) in FIGURES.items():
        r = ratio.get(key)
        lines.append(
            f"{label:44} {_f(one[key]):>12} {_f(two[key]):>12} {'' if r is None else r:>8}"
        )
    lines.append("CPU pressure during the runs:")
    for count in (1, 2):
        lines += [f"  {count}: {run['pressure']}" for run in res["runs"][count]]
    return "\n".join(lines)


def _f(v: float | None) -> str:
    return "n/a" if v is None else f"{v:,.3f}" if abs(v) < 10 else f"{v:,.1f}"


def main(argv: list[str] | None = None) -> int:
    """Run the benchmark and print the figures."""
    args = parse(argv)
    try:
        res = asyncio.run(bench(args))
    except (RuntimeError, OSError) as err:
        print(f"bench/scale.py: {err}", file=sys.stderr)
        return 1
    print(json.dumps(res, indent=2) if args.json else report(res))
    return 0


if __name__ == "__main__":
    sys.exit(main())
