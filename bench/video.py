"""Live video through the embedded relay: glass-to-glass latency, frame rate and server CPU per
viewer at 1, 5 and 10 viewers of one stream, in one run.

    python bench/video.py [--width 640] [--height 480] [--fps 30] [--viewers 1,5,10]
                          [--seconds 10] [--warmup 3] [--json]

One `aerobase server` subprocess (its own SQLite file, loopback ICE allowed) relays a UAV's WHIP
publication to WHEP viewers. The publisher (this process: the agent's CameraTrack and
WhipPublisher, aiortc's VP8 encoder) draws a frame counter into each frame's top rows (16 black or
white blocks) and keeps each counter's capture time; one probe viewer decodes every frame, reads
the counter back and times capture → decoded (glass to glass, one clock). The other viewers are
real WebRTC peers (ICE, DTLS, SRTP, RTCP) that count the frames they receive without decoding them
(the relay's work per viewer is the same; decoding 10 streams here would starve the 2-core machine
the server runs on). Server CPU comes from /proc/<pid>/stat over the measured window. Reference,
same run: the CPU one VP8 encode of this stream costs (what aiortc's MediaRelay would spend per
viewer, beside one decode per stream). The Janus path is not built yet, so there is no Janus
column. A benchmark never fails a build: it exits 0 with its figures.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import os
import platform
import shlex
import subprocess
import sys
import tempfile
import time
import uuid
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import httpx

from aerobase.ports import free_port
from asset_agent.video.rtp import RtpPublisher
from asset_agent.video.source import CameraTrack
from asset_agent.video.whip import WhipPublisher
from asynckit.loopback_ice import loopback_candidates_only
from bench._aerobase import start_server
from bench._load import percentile, process_cpu
from bench._video import Peer, Stamped, encode_reference, set_up
from tests.video.netns.janus_env import Janus, in_private_network


def progress(message: str) -> None:
    print(f"[video] {message}", file=sys.stderr, flush=True)


async def bench(args: argparse.Namespace) -> dict[str, Any]:
    private = in_private_network()
    if not private:
        loopback_candidates_only()  # the bench's peers, like the server, talk over loopback
    camera = {"width": args.width, "height": args.height, "fps": args.fps}
    stamped = Stamped(args.width, args.height, args.fps)
    progress("measuring the reference: one VP8 encode of the stream")
    reference = await asyncio.to_thread(encode_reference, stamped, int(args.fps * 5))
    paths = {}
    for path in args.paths:
        paths[path] = await run_path(path, args, camera, stamped, private)
    pressure = Path("/proc/pressure/cpu").read_text().splitlines()[0]  # noqa: ASYNC240
    return {
        "stream": camera,
        "reference_one_vp8_encode_core_pct": round(reference * 100, 1),
        "paths": paths,
        "machine": {
            "cpus": os.cpu_count(),
            "python": platform.python_version(),
            "cpu_pressure": pressure,
            "private_network": private,
        },
    }


async def run_path(
    path: str,
    args: argparse.Namespace,
    camera: dict[str, Any],
    stamped: Stamped,
    private: bool,
) -> list[dict[str, Any]]:
    """One server (and for janus, one Janus) per path; the same stream and viewer levels."""
    os.environ.update(
        AEROBASE_VIDEO_MAX_VIEWERS=str(max(args.viewers) + 1), AEROBASE_ENVIRONMENT="development"
    )
    os.environ.pop("JANUS_URL", None)
    os.environ.pop("AEROBASE_VIDEO_ICE_LOOPBACK", None)
    if not private:
        os.environ["AEROBASE_VIDEO_ICE_LOOPBACK"] = "true"
    with tempfile.TemporaryDirectory() as tmp:
        janus = None
        if path == "janus":
            janus = Janus(Path(tmp) / "janus", free_port()).start()
            os.environ.update(JANUS_URL=janus.url, AEROBASE_JANUS_RTP_HOST="127.0.0.1")
        superuser = f"root-{uuid.uuid4().hex[:6]}@bench.test"
        server = start_server(Path(tmp), superuser, progress)
        try:
            asset_id, asset_token, viewer_token = await set_up(server.url, superuser, camera)
            track = CameraTrack(stamped.images, args.width, args.height, args.fps)
            sender: asyncio.Task[None] | None = None
            whip: WhipPublisher | None = None
            if path == "janus":
                rtp = RtpPublisher(server.url, asset_id, lambda: asset_token, track)
                sender = asyncio.create_task(rtp.run())
                await asyncio.sleep(2.0)  # the first target, then the stream runs
            else:
                whip = WhipPublisher(
                    f"{server.url}/api/v1/assets/{asset_id}/video/whip", lambda: asset_token, track
                )
                await whip.publish_once()
            rows = []
            pids = [server.pid] + ([janus.proc.pid] if janus and janus.proc else [])
            async with httpx.AsyncClient(base_url=server.url, timeout=30) as api:
                for count in args.viewers:
                    rows.append(
                        await level(
                            api,
                            pids,
                            asset_id,
                            viewer_token,
                            stamped,
                            track,
                            count,
                            args,
                            viewer_offers=path != "janus",
                        )
                    )
            if whip is not None:
                await whip.stop()
            if sender is not None:
                sender.cancel()
            await track.aclose()
        finally:
            server.stop()
            if janus is not None:
                janus.stop()
    return rows


async def level(
    api: httpx.AsyncClient,
    pids: list[int],
    asset_id: str,
    token: str,
    stamped: Stamped,
    track: CameraTrack,
    count: int,
    args: argparse.Namespace,
    viewer_offers: bool,
) -> dict[str, Any]:
    progress(f"{count} viewer(s): connecting")
    peers = [
        Peer(str(api.base_url), asset_id, token, stamped if i == 0 else None) for i in range(count)
    ]
    for p in peers:
        await p.start(api, viewer_offers)
    await asyncio.sleep(args.warmup)
    f0 = [p.frames for p in peers]
    sent0 = track.frames
    peers[0].latencies.clear()
    c0, s0, t0, b0 = cpu_of(pids), process_cpu(pids[0]), time.perf_counter(), sum(os.times()[:2])
    await asyncio.sleep(args.seconds)
    c1, s1, t1, b1 = cpu_of(pids), process_cpu(pids[0]), time.perf_counter(), sum(os.times()[:2])
    span = t1 - t0
    fps = [(p.frames - f) / span for p, f in zip(peers, f0, strict=True)]
    sent_fps = (track.frames - sent0) / span
    lat = peers[0].latencies
    for p in peers:
        await p.stop(api)
    cpu = (c1 - c0) / span if c0 is not None and c1 is not None else None
    row = {
        "viewers": count,
        # the media path's processes: the server, and on the Janus path Janus too
        "server_cpu_core_pct": round(cpu * 100, 1) if cpu is not None else None,
        "server_process_only_core_pct": (
            round((s1 - s0) / span * 100, 1) if s0 is not None and s1 is not None else None
        ),
        # this process: the publisher's encode, every viewer's SRTP and RTCP, the probe's decode
        "bench_process_cpu_core_pct": round((b1 - b0) / span * 100, 1),
        "publisher_fps": round(sent_fps, 1),  # frames the drone's encoder produced
        "probe_fps": round(fps[0], 1),
        "min_viewer_fps": round(min(fps), 1),
        "latency_ms_p50": round((percentile(lat, 50) or 0) * 1000, 1),
        "latency_ms_p95": round((percentile(lat, 95) or 0) * 1000, 1),
        "latency_samples": len(lat),
    }
    progress(json.dumps(row))
    return row


def cpu_of(pids: list[int]) -> float | None:
    """CPU seconds of the media path's processes (the server; with Janus, Janus too)."""
    values = [process_cpu(pid) for pid in pids]
    return None if any(v is None for v in values) else sum(v for v in values if v is not None)


def parse(argv: list[str] | None) -> argparse.Namespace:
    p = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    p.add_argument("--width", type=int, default=640)
    p.add_argument("--height", type=int, default=480)
    p.add_argument("--fps", type=float, default=30.0)
    p.add_argument("--viewers", type=lambda s: [int(v) for v in s.split(",")], default=[1, 5, 10])
    p.add_argument("--seconds", type=float, default=10.0)
    p.add_argument("--warmup", type=float, default=3.0)
    p.add_argument(
        "--paths",
        type=lambda s: s.split(","),
        default=["embedded"],
        help="embedded,janus (janus runs in a private network namespace: the bench re-runs "
        "itself under `unshare -n` with a veth pair, as the tests do)",
    )
    p.add_argument("--json", action="store_true")
    return p.parse_args(argv)


NETWORK = (
    "ip link set lo up && ip link add v0 type veth peer name v1 && "
    "ip addr add 198.18.0.1/24 dev v0 && ip addr add 198.18.0.2/24 dev v1 && "
    "ip link set v0 up && ip link set v1 up"
)


def main(argv: list[str] | None = None) -> int:
    args = parse(argv)
    if "janus" in args.paths and not in_private_network():
        # Janus's ICE will not use loopback: run the whole bench in a private network namespace
        argv = sys.argv[1:] if argv is None else list(argv)
        inner = " ".join(shlex.quote(a) for a in [sys.executable, __file__, *argv])
        return subprocess.call(["unshare", "-n", "sh", "-c", f"{NETWORK} && exec {inner}"])
    result = asyncio.run(bench(args))
    if args.json:
        print(json.dumps(result, indent=2))
        return 0
    s = result["stream"]
    print(
        f"stream {s['width']}x{s['height']} @ {s['fps']} fps VP8; reference: one VP8 encode = "
        f"{result['reference_one_vp8_encode_core_pct']} % of a core"
    )
    for path, levels in result["paths"].items():
        print(f"\n{path} path (media CPU: the server{', plus Janus' if path == 'janus' else ''})")
        print(
            "viewers  media CPU %core  per viewer  server alone  bench CPU %core  probe fps  "
            "min fps  latency p50/p95 ms  publisher fps"
        )
        for r in levels:
            per = (r["server_cpu_core_pct"] or 0) / r["viewers"]
            print(
                f"{r['viewers']:7d}  {r['server_cpu_core_pct']:14}  {per:10.1f}  "
                f"{r['server_process_only_core_pct']:12}  "
                f"{r['bench_process_cpu_core_pct']:15}  {r['probe_fps']:9}  "
                f"{r['min_viewer_fps']:7}  {r['latency_ms_p50']}/{r['latency_ms_p95']}  "
                f"{r['publisher_fps']}"
            )
        if len(levels) > 1:
            first, last = levels[0], levels[-1]
            slope = (last["server_cpu_core_pct"] - first["server_cpu_core_pct"]) / max(
                1, last["viewers"] - first["viewers"]
            )
            ratio = slope / max(0.1, result["reference_one_vp8_encode_core_pct"])
            print(
                f"marginal media CPU per added viewer: {slope:.1f} % of a core "
                f"({ratio:.2f}x one VP8 encode)"
            )
    print(f"\nmachine: {result['machine']}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
