"""The landing-base daemon's server link: protocol/link.py wired to the Station.

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
from asynckit.tasks import cancel_and_wait
from base_station.base_telemetry import AxisTelemetry, StationTelemetry
from base_station.config import StationConfig
from base_station.events import Event, EventKind
from base_station.rtk import RtkConfig as ReaderConfig
from base_station.rtk import RtkReader, source_url, to_telemetry
from base_station.station import Progress, Result, Station
from protocol.messages import CommandProgress, CommandResultPayload, EventPayload, Severity
from protocol.telemetry_payloads import (
    Actuator,
    Charger,
    Faults,
    LandingBaseTelemetry,
    Power,
    Rtk,
    Weather,
)
from protocol.vocabulary import CommandParams

log = logging.getLogger(__name__)

CRITICAL = {EventKind.ESTOP, EventKind.PLC_LINK_LOST, EventKind.FAULT, EventKind.MOTION_FAILED}
WARNING = {EventKind.REFUSAL, EventKind.PLC_INTERLOCK_REFUSED}
MOTION = {"closed", "opening", "open", "closing", "moving", "fault", "stopped"}


def _axis(a: AxisTelemetry) -> Actuator | None:
    if a.state is None:
        return None
    state = a.state if a.state in MOTION else "stopped"
    pct = None if a.position_pct is None else min(100.0, max(0.0, a.position_pct))
    return Actuator(state=state, position_pct=pct)  # type: ignore[arg-type]


def to_protocol(t: StationTelemetry, rtk: Rtk | None = None) -> LandingBaseTelemetry:
    """The wire form of one station telemetry sample (pure)."""
    w, c, p = t.weather, t.charger, t.power
    return LandingBaseTelemetry(
        plc_link="up" if t.plc_link == "up" else "down",
        panels=_axis(t.panels),
        lift=_axis(t.lift),
        uav_present=t.uav_present,
        landing_confirmed=t.landing_confirmed,
        scale_mass_g=None if t.scale_mass_g is None else max(0.0, t.scale_mass_g),
        weather=None
        if w is None
        else Weather(
            wind_m_s=max(0.0, w.wind_mps),
            gust_m_s=max(0.0, w.gust_mps),
            direction_deg=w.direction_deg % 360,
            rain_mm_h=max(0.0, w.rain_mm_h),
            rain_detected=w.rain_detected,
            temperature_c=w.temperature_c,
            humidity_pct=min(100.0, max(0.0, w.humidity_pct)),
        ),
        charger=None
        if c is None
        else Charger(
            state=c.state if c.state in ("idle", "charging", "complete", "fault") else "idle",  # type: ignore[arg-type]
            enabled=c.enabled,
            contact=c.contacts_seated,
            current_a=c.current_ma / 1000,
            voltage_v=c.voltage_v,
            uav_battery_pct=None
            if c.uav_battery_pct is None
            else min(100.0, max(0.0, c.uav_battery_pct)),
        ),
        power=None
        if p is None
        else Power(
            source=p.source if p.source in ("grid", "solar", "battery") else None,  # type: ignore[arg-type]
            battery_pct=min(100.0, max(0.0, p.base_battery_pct)),
            battery_v=p.base_battery_voltage_v,
            solar_w=max(0, p.solar_w),
            grid_present=p.grid_present,
        ),
        rtk=rtk,
        estop=t.estop,
        faults=Faults.from_bits(t.fault_bits or 0),
    )


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
        reader = None
        if config.rtk.tcp_port or config.rtk.serial_device:
            reader = RtkReader(
                ReaderConfig(source=source_url(**config.rtk.model_dump())), on_frame=link.send_rtcm
            )
            reader.start()
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
                    await link.send_telemetry(to_protocol(station.telemetry(), rtk))
                except Exception:  # one bad sample must not take the link down with it
                    failures += 1
                    if failures <= 3 or failures % 100 == 0:
                        log.exception("telemetry sample %d could not be sent", failures)
                await asyncio.sleep(period)  # the telemetry rate itself
        finally:
            await cancel_and_wait([forwarder])
            events.close()
            if reader:
                await reader.stop()
            await link.stop()

    return serve
