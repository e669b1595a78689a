"""`aerobase agent --config agent.toml`: the companion-computer daemon.

setup() reads the configuration and the encrypted asset file; run() keeps the autopilot link and
the server link, reports telemetry and events, answers commands and injects RTK corrections;
main() is the console entry point. RTK corrections come from the base's stream on the site's
network when one is configured, else (or while it is silent) through the server (corrections.py). If the server link drops, the flight goes on: the autopilot
flies its mission and everything the agent reports waits in the link's on-disk outbox. The
landing is the agent's too: precision landing (precland/supervisor.py) follows the autopilot, not
the server, so the mission's own return-home lands on the pad with it; when the link returns the
server learns of the landing from the outbox, and its late return_to_base is answered "already
landed" (handlers.py) instead of sending the UAV back into RTL. Restarted in flight, the agent
reads the mission off the autopilot (its last item may already fly home), tells no arming or
take-off for the flight it finds (events.py), and takes up a landing it was flying itself, as its
state file says (precland/resume.py).
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import logging
import signal
import sys
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

from asset_agent.autopilot import Autopilot, AutopilotConfig, AutopilotError
from asset_agent.autopilot.config import DEFAULT_STREAMS
from asset_agent.availability import AvailabilityLimits
from asset_agent.config import AgentConfig
from asset_agent.corrections import Corrections
from asset_agent.events import EventLimits, EventTracker
from asset_agent.handlers import Handlers
from asset_agent.metrics import families
from asset_agent.precland.readiness import PrecisionLandingCheck
from asset_agent.precland.supervisor import PrecisionLander, stream_rates
from asset_agent.uav_telemetry import to_event, to_telemetry
from asset_agent.video.publish import VideoPublisher, video_publisher
from assetlink.configfile import AssetConfig, ConfigFileError
from assetlink.configfile_cli import PasswordSourceError, load_config
from assetlink.link import Link
from assetlink.metrics import DaemonMetrics, MetricsServer
from assetlink.rtk import RtkConfig, RtkReader
from assetlink.settings import LinkSettings
from assetlink.statefile import StateFileError
from asynckit.tasks import cancel_and_wait

log = logging.getLogger("asset_agent")


@dataclass
class Agent:
    """The daemon's parts, built by setup()."""

    config: AgentConfig
    asset: AssetConfig
    autopilot: Autopilot
    link: Link
    tracker: EventTracker
    lander: PrecisionLander | None = None
    corrections: Corrections | None = None  # RTK corrections into the autopilot
    local_rtk: RtkReader | None = None  # the base's stream on the site's network, if configured


def setup(config: AgentConfig, asset: AssetConfig) -> Agent:
    """Build the autopilot adapter and the server link; nothing connects yet."""
    ap = config.autopilot
    precland = config.precland.active
    streams = {**DEFAULT_STREAMS, **(stream_rates(config.precland) if precland else {})}
    autopilot = Autopilot(
        AutopilotConfig(
            url=ap.url,
            link_timeout_s=ap.link_timeout_s,
            command_timeout_s=ap.command_timeout_s,
            streams=streams,
        )
    )
    link = Link(
        config.server.url or asset.server_url,
        asset.name,
        asset.secret,
        config.server.state_file.expanduser(),
        LinkSettings(max_outbox=config.server.max_outbox),
        agent="asset_agent",
    )
    limits = AvailabilityLimits(
        config.availability.min_battery_pct, config.availability.min_fix_type
    )
    landing_target = precland and config.precland.mode == "landing_target"
    checks = [PrecisionLandingCheck(autopilot)] if landing_target else []
    for command, handler in Handlers(autopilot, limits, checks).table().items():
        link.on_command(command.name, handler)

    # RTK corrections: the base's local stream first, the server's relay while it is silent
    corrections = Corrections(autopilot.inject_rtcm, config.rtk.local_silence_s)
    link.on_rtcm(corrections.from_server)
    local = None
    if config.rtk.local_source:
        source = RtkConfig(source=config.rtk.local_source, reconnect_max_s=2.0)
        local = RtkReader(source, on_frame=corrections.from_local_async)
    lander = PrecisionLander(autopilot, config.precland, link) if precland else None
    if lander is not None:
        link.on_command("precland_fault", lander.fault_command)
    tracker = EventTracker(EventLimits(low_battery_pct=config.telemetry.low_battery_pct))
    return Agent(config, asset, autopilot, link, tracker, lander, corrections, local)


async def _report(agent: Agent, stop: asyncio.Event) -> None:
    """Telemetry at the configured rate; events from state changes and autopilot notifications."""
    period = 1.0 / agent.config.telemetry.rate_hz
    notes = agent.autopilot.subscribe()
    try:
        failures = 0
        while not stop.is_set():
            try:
                state = agent.autopilot.state
                heard = [notes.get_nowait() for _ in range(notes.qsize())]
                events = agent.tracker.feed(heard, state)
                if agent.lander is not None:
                    events += agent.lander.drain_events()
                for event in events:
                    blind = None
                    if event.kind == "landed" and agent.lander is not None:
                        event = agent.lander.with_touchdown(event)
                        blind = agent.lander.silence.blind_landing(event.detail["landing_path"])
                    await agent.link.send_event(to_event(event))
                    if blind is not None:  # its sensors watched, it did not steer: said so
                        await agent.link.send_event(to_event(blind))
                if state.link_up:
                    await agent.link.send_telemetry(to_telemetry(state))
            except Exception:  # a bad sample is logged and skipped; the daemon keeps reporting
                failures += 1
                if failures <= 3 or failures % 100 == 0:
                    log.exception("report %d failed", failures)
            with contextlib.suppress(TimeoutError):
                await asyncio.wait_for(stop.wait(), period)
    finally:
        agent.autopilot.unsubscribe(notes)


async def _adopt_mission(agent: Agent) -> None:
    """The mission already on the autopilot, read once it answers: started after the upload (a
    restart, in flight perhaps), the agent would not know that the mission's last item flies
    home, and would answer the run's return to the base with an RTL on top of it."""
    try:
        await agent.autopilot.wait_link(None)
        await agent.autopilot.adopt_mission()
    except AutopilotError as err:
        log.warning("the mission on the autopilot could not be read: %s", err)


async def _publish(agent: Agent, video: VideoPublisher) -> None:
    """The camera to the server once the link has a session: a WHIP offer without its bearer
    token would only be refused (401) and retried."""
    await agent.link.wait_connected()
    await video.run()


async def run(agent: Agent, stop: asyncio.Event | None = None) -> None:
    """Run until `stop` is set (or forever)."""
    stop = stop or asyncio.Event()
    await agent.autopilot.start()
    await agent.link.start()
    if agent.local_rtk is not None:
        agent.local_rtk.start()
    log.info(
        "agent %s running: autopilot %s, server %s",
        agent.asset.name,
        agent.config.autopilot.url,
        agent.link.server_url,
    )
    adopting = asyncio.create_task(_adopt_mission(agent), name="adopt-mission")
    lander = None
    if agent.lander is not None:
        lander = asyncio.create_task(agent.lander.run(stop), name="precland")
    video = video_publisher(
        agent.config, agent.link.server_url, agent.asset.asset_id, lambda: agent.link.token
    )
    publishing = None
    if video is not None:
        publishing = asyncio.create_task(_publish(agent, video), name="video")
    metrics = None
    if agent.config.metrics.port:
        collector = DaemonMetrics(agent.link, lambda: families(agent.autopilot))
        metrics = MetricsServer(collector, agent.config.metrics.host, agent.config.metrics.port)
    try:
        await _report(agent, stop)
    finally:
        if metrics:
            metrics.close()
        await cancel_and_wait([adopting, lander, publishing])
        if video is not None:
            await video.stop()
            await video.track.aclose()
        if agent.local_rtk is not None:
            await agent.local_rtk.stop()
        await agent.link.stop()
        await agent.autopilot.close()


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of `aerobase agent`."""
    parser = argparse.ArgumentParser(prog="aerobase agent")
    parser.add_argument("--config", required=True, help="agent.toml")
    args = parser.parse_args(argv)
    logging.basicConfig(
        level=logging.INFO, format="%(asctime)s %(levelname)s %(name)s: %(message)s"
    )
    logging.getLogger("httpx").setLevel(logging.WARNING)  # else a line per login and refresh
    try:
        config = AgentConfig.load(args.config)
        pw = str(config.server.password_file.expanduser()) if config.server.password_file else None
        asset = load_config(config.server.config_file.expanduser(), pw)
    except (OSError, ValueError, ConfigFileError, PasswordSourceError) as err:
        print(f"aerobase agent: {err}", file=sys.stderr)
        return 1
    if asset.kind != "uav":
        print(
            f"aerobase agent: {Path(config.server.config_file)} is a {asset.kind}'s file, not a UAV's",
            file=sys.stderr,
        )
        return 1
    agent = setup(config, asset)

    async def _main() -> None:
        stop = asyncio.Event()
        loop = asyncio.get_running_loop()
        for sig in (signal.SIGINT, signal.SIGTERM):
            loop.add_signal_handler(sig, stop.set)
        await run(agent, stop)

    try:
        asyncio.run(_main())
    except StateFileError as err:
        print(f"aerobase agent: {err}", file=sys.stderr)
        return 1
    return 0
