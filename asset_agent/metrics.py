"""The agent's own Prometheus families (served by assetlink.metrics beside its server link's):
the MAVLink link and its command round trips. Read at scrape time; one UAV's figures."""

from __future__ import annotations

from collections.abc import Iterator

from prometheus_client.core import CounterMetricFamily, Metric

from asset_agent.autopilot import Autopilot
from assetlink.metrics import gauge, round_trips


def families(autopilot: Autopilot) -> Iterator[Metric]:
    """MAVLink families of this agent now."""
    yield from gauge(
        "aerobase_mavlink_link_up",
        "1 while the autopilot's HEARTBEAT keeps arriving",
        float(autopilot.link_up),
    )
    yield from round_trips(
        "aerobase_mavlink_command_round_trip_seconds",
        "A COMMAND_LONG sent to the autopilot until its final COMMAND_ACK",
        autopilot.round_trips,
    )
    reboots = CounterMetricFamily("aerobase_mavlink_reboots", "Autopilot reboots seen")
    reboots.add_metric([], autopilot.reboots)
    yield reboots
