"""The landing-base daemon's server link: assetlink/link.py wired to the Station.

Commands from the server run through `Station.execute` (progress, then one result); the
station's events and its telemetry go out through the link's durable outbox; RTCM3 frames from
the GNSS reference receiver go out as `rtcm` messages.
"""

from __future__ import annotations

import asyncio
import logging
from collections.abc import AsyncIterator
from pathlib import Path

from assetlink.configfile import AssetConfig
from assetlink.dispatch import CommandRequest, Handler
from assetlink.link import Link
from assetlink.metrics import DaemonMetrics, MetricsServer
from assetlink.rtk import RtkConfig as ReaderConfig
from assetlink.rtk import RtkReader, source_url, to_telemetry
from asynckit.tasks import cancel_and_wait
from base_station.config import StationConfig
from base_station.events import Event, EventKind
from base_station.metrics import families
from base_station.rtcm_server import RtcmServer
from base_station.station import Progress, Result, Station
from protocol.messages import CommandProgress, CommandResultPayload, EventPayload, Severity
from protocol.vocabulary import CommandParams

log = logging.getLogger(__name__)

CRITICAL = {EventKind.ESTOP, EventKind.PLC_LINK_LOST, EventKind.FAULT, EventKind.MOTION_FAILED}
WARNING = {EventKind.REFUSAL, EventKind.PLC_INTERLOCK_REFUSED, EventKind.WATCHDOG_RECOVERED}


def to_event(e: Event) -> EventPayload:
    """The wire form of one station event (pure)."""
    severity: Severity = (
        "critical" if e.kind in CRITICAL else "warning" if e.kind in WARNING else "info"
    )
    return EventPayload(name=e.kind.value, severity=severity, message=e.message, data=dict(e.data))


def command_handler(station: Station) -> Handler:
    """A link handler running the station's typed commands, progress numbered as it comes."""

    async def handler(
        request: CommandRequest[CommandParams],
    ) -> AsyncIterator[CommandProgress | CommandResultPayload]:
        index = 0
        async for item in station.execute(request.command):
            if isinstance(item, Progress):
                index += 1
                yield CommandProgress(
                    step=item.step, index=index, total=max(index, 2), message=item.message
                )
            elif isinstance(item, Result):
                yield CommandResultPayload(
                    status=item.status.value, reason=item.reason, data=item.data
                )  # type: ignore[arg-type]
                return

    return handler


def make_link(asset: AssetConfig, state_file: Path, server_url: str | None = None) -> Link:
    """The link of this base (state kept in `state_file` across restarts)."""
    return Link(
        server_url or asset.server_url, asset.name, asset.secret, state_file, agent="base_station"
    )


def link_runner(link: Link):  # type: ignore[no-untyped-def]
    """A `base_station.main.LinkRunner` serving `link`."""

    async def serve(station: Station, config: StationConfig) -> None:
        handler = command_handler(station)
        for command in station.commands:
            link.on_command(command.name, handler)
        await link.start()
        reader = rtcm = None
        rc = config.rtk
        if rc.tcp_port or rc.serial_device:
            source = source_url(rc.tcp_host, rc.tcp_port, rc.serial_device, rc.baudrate)
            reader = RtkReader(ReaderConfig(source=source), on_frame=link.send_rtcm)
            reader.start()
            if rc.serve_port:  # the corrections' path beside the server's (rtcm_server.py)
                rtcm = RtcmServer(reader, rc.serve_host, rc.serve_port)
                await rtcm.start()
        metrics = None
        if config.metrics.port:
            collector = DaemonMetrics(link, lambda: families(station.coord, reader))
            metrics = MetricsServer(collector, config.metrics.host, config.metrics.port)
        events = station.subscribe()

        async def forward_events() -> None:
            async for event in events:
                try:
                    await link.send_event(to_event(event))
                except Exception:
                    log.exception("event %s could not be sent", event.kind)

        forwarder = asyncio.create_task(forward_events())
        try:
            period = 1.0 / config.telemetry_hz
            failures = 0
            while True:
                try:
                    rtk = to_telemetry(reader.stats()) if reader else None
                    await link.send_telemetry(station.telemetry(rtk))
                except Exception:  # one bad sample must not take the link down with it
                    failures += 1
                    if failures <= 3 or failures % 100 == 0:
                        log.exception("telemetry sample %d could not be sent", failures)
                await asyncio.sleep(period)  # the telemetry rate itself
        finally:
            await cancel_and_wait([forwarder])
            events.close()
            if metrics:
                metrics.close()
            if rtcm:
                await rtcm.close()
            if reader:
                await reader.stop()
            await link.stop()

    return serve
