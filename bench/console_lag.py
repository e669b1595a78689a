"""Console lag under load: how long a UAV's telemetry takes to reach the operator console's fleet
page in a real browser, beside its delivery to a plain operator socket in the same run.

    python bench/console_lag.py [--fleet 200] [--loads 1,50,200] [--rate 5] [--seconds 20]
                                [--repeats 3] [--no-maps] [--render-all] [--json]

One `aerobase server` (a subprocess, its own SQLite file or DATABASE_URL), a fleet of `--fleet`
UAVs and one landing base surveyed at BASE_AT registered through the API, and Debian's headless
Chromium (Playwright) signed in as a viewer on the fleet page, which draws a card for every UAV
with its live track map around the base (`--no-maps`: no base, no maps). `--render-all` makes the
browser lay out and paint every card, off screen too, as the console did before its cards had
`content-visibility: auto` (a style added with the page's CSP bypassed): what that rule gives. At each load, that many of the UAVs send
telemetry at `--rate` Hz over their own /ws/asset sockets. UAV 0 is the probe: each of its
samples carries its own altitude (a value the card shows to 0.1 m), sent at a recorded wall-clock
time. The page's MutationObserver notes when the probe card's altitude changes to each value
(`Date.now()`, the same clock: one machine), so the console's lag is send → DOM updated on the
page (the paint follows in the same frame). The reference, in the same run, is a plain viewer
socket on /ws/operator subscribed to the probe: send → delivered. The ratio of the two medians is
what the browser adds (parsing, the animation frame that batches card updates, re-rendering the
cards). `shown` is the share of probe samples the page drew: a card updated less often than the
probe sends (frames slower than 1/rate) skips values, and that is lag too.

Each load also records the CPU the browser (every Chromium process) and the server took, in % of
one core, and the page's CPU while idle comes first: here the browser, the server and the load
generator share one machine, where an operator's browser has its own. The machine is shared too:
every load records its CPU pressure (/proc/pressure/cpu); above 10 % the figures say more about
the machine than about the console, and the report says so. A benchmark
never fails a build: it exits 0 with the figures, non-zero only when it could not run.

Before the loads, the fleet page's video panels: none of the UAVs publishes video, so each panel
should settle on "no signal" without opening a viewer session. The benchmark records how long
after the sign-in every panel has left "starting" and how many WHEP offers the page made.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import statistics
import sys
import tempfile
import time
import uuid
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import httpx
import orjson

from bench._aerobase import (
    USER_PASSWORD,
    Fleet,
    _asset,
    _operator,
    closed_codes,
    set_up,
    start_server,
)
from bench._lean import LeanSocket
from bench._load import Payloads, percentile, process_cpu, sample
from bench.telemetry import BUSY_PRESSURE_PCT, cpu_pressure, pressure_between
from protocol.codec import encode
from protocol.messages import envelope

CHROMIUM = "/usr/bin/chromium"  # Debian's, as the console tests use (.ci/install-system.sh)
BASE_AT = (41.0, -8.6)  # the one surveyed base: the UAVs' samples circle 0.01° steps from it
RENDER_ALL = ".stack-cards > .card { content-visibility: visible !important; }"
ALT0, ALT_STEP, ALT_VALUES = 10.0, 0.1, 900  # the probe's altitudes: unique over 180 s at 5 Hz

WATCH = """name => {
  const card = [...document.querySelectorAll("h2")].find((h) => h.textContent === `UAV ${name}`)
    .closest("section");
  window.__seen = [];
  const read = () => {
    for (const dt of card.querySelectorAll("dt")) {
      if (dt.textContent === "Altitude") {
        window.__seen.push([Date.now(), parseFloat(dt.nextElementSibling.textContent)]);
      }
    }
  };
  if (window.__observer) window.__observer.disconnect(); // one observer, not one per load
  window.__observer = new MutationObserver(read);
  window.__observer.observe(card, { childList: true, subtree: true, characterData: true });
}"""


def progress(text: str) -> None:
    print(f"[console-lag {time.strftime('%H:%M:%S')}] {text}", file=sys.stderr, flush=True)


def parse(argv: list[str] | None) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--fleet", type=int, default=200, help="UAVs registered (cards on the page)")
    p.add_argument("--loads", default="1,50,200", help="UAVs sending, per load (probe included)")
    p.add_argument("--rate", type=float, default=5.0, help="telemetry per UAV per second")
    p.add_argument("--seconds", type=float, default=20.0, help="measured seconds per load")
    p.add_argument("--repeats", type=int, default=3, help="runs of every load (median reported)")
    p.add_argument(
        "--no-maps",
        dest="maps",
        action="store_false",
        help="no surveyed base, so no UAV card draws its live track map",
    )
    p.add_argument(
        "--render-all",
        action="store_true",
        help="lay out and paint every card, off screen too (the console before content-visibility)",
    )
    p.add_argument("--json", action="store_true", help="print the result as JSON too")
    args = p.parse_args(argv)
    args.loads = [int(x) for x in args.loads.split(",")]
    if max(args.loads) > args.fleet or min(args.loads) < 1:
        p.error("every load must be between 1 and --fleet")
    return args


def _probe_text(k: int) -> str:
    """Probe sample k: the fleet's sample with an altitude of its own."""
    s = sample(0, k)
    alt = round(ALT0 + ALT_STEP * (k % ALT_VALUES), 1)
    s = s.model_copy(update={"position": s.position.model_copy(update={"alt_rel_m": alt})})
    return encode(envelope(s, seq=k + 1, id=uuid.uuid4(), ts=int(time.time() * 1000)))


def _browser_cpu() -> float:
    """CPU seconds of every Chromium process on the machine (the benchmark's browser: the
    console's parsing, layout and painting; none other runs beside it)."""
    total = 0.0
    for comm in Path("/proc").glob("[0-9]*/comm"):
        try:
            name = comm.read_text().strip()
        except OSError:
            continue
        if name in ("chromium", "chrome", "headless_shell"):
            total += process_cpu(int(comm.parent.name)) or 0.0
    return total


SETTLED = """() => [...document.querySelectorAll("p.video-state")].map((p) => p.dataset.state || "starting")"""


async def _video_settled(page: Any, signed_in: float, within_s: float = 60.0) -> dict[str, Any]:
    """How long after the sign-in until every UAV card's video panel has left "starting" (the
    panels of idle UAVs say "no signal"), polled every 0.1 s; and what they say then."""
    states: list[str] = []
    while time.perf_counter() - signed_in < within_s:
        states = await page.evaluate(SETTLED)
        if states and "starting" not in states:
            break
        await asyncio.sleep(0.1)
    counts = {k: states.count(k) for k in sorted(set(states))}
    done = bool(states) and "starting" not in states
    return {
        "settled_s": round(time.perf_counter() - signed_in, 2) if done else None,
        "states": counts,
    }


def _index(alt: float) -> int:
    return round((alt - ALT0) / ALT_STEP)


async def _sign_in(page: Any, email: str) -> None:
    """The console's sign-in form; the account's other session (its API login) is ended."""
    await page.get_by_label("E-mail").fill(email)
    await page.get_by_label("Password").fill(USER_PASSWORD)
    await page.get_by_label("Password").press("Enter")
    fleet = page.get_by_role("heading", name="Fleet", exact=True)
    take_over = page.get_by_role("button", name="Sign in and end the other session")
    await fleet.or_(take_over).first.wait_for(timeout=60_000)
    if await take_over.is_visible():
        await take_over.click()
    await fleet.wait_for(timeout=60_000)


async def _load(
    args: argparse.Namespace,
    n: int,
    page: Any,
    fleet: Fleet,
    sockets: list[LeanSocket],
    payloads: Payloads,
    delivered: dict[int, float],
    first: int,
    server_pid: int,
) -> dict[str, Any]:
    """One load: `n` UAVs sending for `--seconds` from tick `first` (every socket's seqs go on
    rising across loads); the probe's lags on the page and on the socket."""
    await page.evaluate(WATCH, fleet.names[0])
    delivered.clear()
    sent: dict[int, float] = {}
    period = 1.0 / args.rate
    pressure = cpu_pressure()
    cpu = (_browser_cpu(), process_cpu(server_pid) or 0.0, time.perf_counter())
    start = time.perf_counter() + 0.2
    for tick in range(int(args.seconds * args.rate)):
        await asyncio.sleep(max(0.0, start + tick * period - time.perf_counter()))
        k = first + tick
        sent[k % ALT_VALUES] = time.time() * 1000
        sockets[0].send(_probe_text(k))
        for i in range(1, n):  # the others after it, yielding now and then
            sockets[i].send(payloads.text(i, k + 1))
            if i % 32 == 31:
                await asyncio.sleep(0)
    await asyncio.sleep(2.0)  # what is still in flight arrives (no figure rests on this wait)
    busy = pressure_between(pressure, cpu_pressure())
    wall = time.perf_counter() - cpu[2]
    browser_pct = round(100 * (_browser_cpu() - cpu[0]) / wall)
    server_pct = round(100 * ((process_cpu(server_pid) or 0.0) - cpu[1]) / wall)
    seen: dict[int, float] = {}
    for at, alt in await page.evaluate("window.__seen"):
        if alt == alt:  # not NaN ("–")
            seen.setdefault(_index(alt) % ALT_VALUES, at)
    page_ms = [seen[k] - t for k, t in sent.items() if k in seen]
    socket_ms = [delivered[k] - t for k, t in sent.items() if k in delivered]
    row = {
        "sending": n,
        "probe_sent": len(sent),
        "shown_pct": round(100 * len(page_ms) / len(sent), 1),
        "delivered_pct": round(100 * len(socket_ms) / len(sent), 1),
        "page_p50_ms": percentile(page_ms, 50),
        "page_p95_ms": percentile(page_ms, 95),
        "page_max_ms": max(page_ms, default=None),
        "socket_p50_ms": percentile(socket_ms, 50),
        "socket_p95_ms": percentile(socket_ms, 95),
        "cpu_pressure_pct": busy,
        "browser_cpu_pct": browser_pct,  # of one core, over the load and its 2 s drain
        "server_cpu_pct": server_pct,
    }
    p50, s50 = row["page_p50_ms"], row["socket_p50_ms"]
    row["ratio_p50"] = round(p50 / s50, 2) if p50 and s50 else None
    return row


async def bench(args: argparse.Namespace) -> dict[str, Any]:
    from playwright.async_api import async_playwright

    superuser = f"root-{uuid.uuid4().hex[:6]}@bench.test"
    with tempfile.TemporaryDirectory(prefix="console-lag-") as tmp:
        server = await asyncio.to_thread(start_server, Path(tmp), superuser, progress)
        try:
            fleet = await set_up(
                server.url, superuser, args.fleet, 2, progress, BASE_AT if args.maps else None
            )
            delivered: dict[int, float] = {}

            def on_probe(raw: bytes) -> None:
                msg = orjson.loads(raw)
                if msg.get("type") == "telemetry":
                    alt = msg["payload"]["position"]["alt_rel_m"]
                    delivered.setdefault(_index(alt) % ALT_VALUES, time.time() * 1000)

            reference = await _operator(
                server.url, fleet.viewer_tokens[0], fleet.asset_ids[:1], on_probe
            )
            async with httpx.AsyncClient(base_url=server.url, timeout=60) as api:
                sockets = [
                    await _asset(server.url, name, secret, api, lambda raw: None)
                    for name, secret in zip(
                        fleet.names[: max(args.loads)], fleet.secrets, strict=False
                    )
                ]
            progress(f"{len(sockets)} UAV sockets and the reference viewer socket connected")
            payloads = Payloads(max(args.loads))
            async with async_playwright() as pw:
                browser = await pw.chromium.launch(
                    executable_path=CHROMIUM, headless=True, args=["--no-sandbox"]
                )
                page = await (
                    await browser.new_context(
                        viewport={"width": 1280, "height": 800}, bypass_csp=args.render_all
                    )
                ).new_page()
                offers: list[str] = []
                page.on(
                    "request",
                    lambda r: (
                        offers.append(r.url)
                        if r.method == "POST" and r.url.endswith("/video/whep")
                        else None
                    ),
                )
                await page.goto(server.url + "/")
                if args.render_all:
                    await page.add_style_tag(content=RENDER_ALL)
                signed_in = time.perf_counter()
                await _sign_in(page, fleet.viewer_emails[1])
                await page.get_by_role("heading", name=f"UAV {fleet.names[0]}").wait_for(
                    timeout=60_000
                )
                progress(f"the console shows the fleet page ({args.fleet} UAV cards)")
                video = await _video_settled(page, signed_in)
                video["whep_offers"] = len(offers)
                progress(
                    f"every video panel settled {video['settled_s']} s after the sign-in: "
                    f"{video['states']}, {len(offers)} WHEP offers (no UAV publishes)"
                )
                await asyncio.sleep(5.0)  # its first requests done: then idle, nothing sent
                idle = (_browser_cpu(), time.perf_counter())
                await asyncio.sleep(10.0)
                idle_pct = round(100 * (_browser_cpu() - idle[0]) / (time.perf_counter() - idle[1]))
                progress(f"the page idle (no telemetry): browser CPU {idle_pct} % of a core")
                runs: dict[int, list[dict[str, Any]]] = {n: [] for n in args.loads}
                first = 0
                for r in range(args.repeats):
                    for n in args.loads:
                        row = await _load(
                            args, n, page, fleet, sockets, payloads, delivered, first, server.pid
                        )
                        first += int(args.seconds * args.rate)
                        runs[n].append(row)
                        row["closed_by_server"] = closed_codes([reference, *sockets])
                        progress(f"repeat {r + 1}/{args.repeats}, {n} sending: {_line(row)}")
                await browser.close()
            reference.close()
            for ws in sockets:
                ws.close()
        finally:
            server.stop()
    return {
        "args": {k: v for k, v in vars(args).items() if k != "json"},
        "idle_browser_cpu_pct": idle_pct,
        "video_panels": video,
        "loads": {n: _median(rows) for n, rows in runs.items()},
        "runs": runs,
    }


def _median(rows: list[dict[str, Any]]) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for key in rows[0]:
        values = [r[key] for r in rows if r[key] is not None]
        numbers = all(isinstance(v, int | float) for v in values)
        out[key] = (statistics.median(values) if numbers else values[-1]) if values else None
    return out


def _f(v: Any, unit: str = "") -> str:
    return "–" if v is None else f"{v:.0f}{unit}" if isinstance(v, float) else f"{v}{unit}"


def _line(row: dict[str, Any]) -> str:
    return (
        f"page p50 {_f(row['page_p50_ms'], ' ms')} p95 {_f(row['page_p95_ms'], ' ms')} "
        f"(shown {row['shown_pct']} %), socket p50 {_f(row['socket_p50_ms'], ' ms')} "
        f"p95 {_f(row['socket_p95_ms'], ' ms')}, ratio {row['ratio_p50']}, "
        f"CPU pressure {_f(row['cpu_pressure_pct'], ' %')}, browser CPU "
        f"{row['browser_cpu_pct']} %, server CPU {row['server_cpu_pct']} %, sockets the server closed "
        f"{row.get('closed_by_server') or 'none'}"
    )


def report(res: dict[str, Any]) -> str:
    a = res["args"]
    lines = [
        f"Console lag: fleet page of {a['fleet']} UAV cards in headless Chromium, {a['rate']:g} Hz per "
        f"UAV, {a['seconds']:g} s per load, median of {a['repeats']} repeats; "
        f"{'maps drawn' if a['maps'] else 'no maps'}, "
        f"{'every card rendered' if a['render_all'] else 'off-screen cards skipped'}",
        "| UAVs sending | page p50 / p95 ms | shown | socket p50 / p95 ms | page / socket (p50) "
        "| browser / server CPU, % of a core | CPU pressure |",
        "|---|---|---|---|---|---|---|",
    ]
    v = res["video_panels"]
    lines[1:1] = [
        f"Video panels (no UAV publishes): every one settled {v['settled_s']} s after the "
        f"sign-in, {v['states']}, {v['whep_offers']} WHEP offers; idle page "
        f"{res['idle_browser_cpu_pct']} % of a core"
    ]
    for n, row in res["loads"].items():
        busy = row["cpu_pressure_pct"]
        flag = " (busy)" if busy is not None and busy > BUSY_PRESSURE_PCT else ""
        lines.append(
            f"| {n} | {_f(row['page_p50_ms'])} / {_f(row['page_p95_ms'])} | {row['shown_pct']} % | "
            f"{_f(row['socket_p50_ms'])} / {_f(row['socket_p95_ms'])} | {row['ratio_p50']} | "
            f"{_f(row['browser_cpu_pct'])} / {_f(row['server_cpu_pct'])} | {_f(busy, ' %')}{flag} |"
        )
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    """Run the benchmark; 0 with figures whatever they are, 2 when it could not run."""
    args = parse(argv)
    try:
        res = asyncio.run(bench(args))
    except Exception as err:
        print(f"bench/console_lag.py could not run: {type(err).__name__}: {err}", file=sys.stderr)
        return 2
    print(report(res))
    if args.json:
        print(json.dumps(res, separators=(",", ":"), default=str))
    return 0


if __name__ == "__main__":
    sys.exit(main())
