"""The daemons' own /metrics: the base-station daemon and the agent each serve Prometheus text on
a local port (off by default), which prometheus-client's own parser reads, with their server
link, outbox, PLC or MAVLink round trips and RTK correction age."""

from __future__ import annotations

import math

import httpx
import pytest
from prometheus_client.parser import text_string_to_metric_families

from aerobase.ports import free_port
from asset_agent.config import AgentConfig
from base_station.config import StationConfig
from tests.conftest import Tenant
from tests.e2e.harness import platform
from tests.metrics import value
from tests.polling import eventually

pytestmark = pytest.mark.slow

LINK = {
    "aerobase_server_link_up",
    "aerobase_outbox_depth",
    "aerobase_outbox_messages",
    "aerobase_server_link_reconnects",
}
BASE = LINK | {
    "aerobase_plc_link_up",
    "aerobase_plc_read_round_trip_seconds",
    "aerobase_plc_read_round_trip_seconds_last",
    "aerobase_plc_polls",
    "aerobase_rtk_state",
    "aerobase_rtk_correction_age_seconds",
    "aerobase_rtk_corrections_per_second",
    "aerobase_rtk_frames",
}
AGENT = LINK | {
    "aerobase_mavlink_link_up",
    "aerobase_mavlink_command_round_trip_seconds",
    "aerobase_mavlink_command_round_trip_seconds_last",
    "aerobase_mavlink_reboots",
}


def test_the_daemons_metrics_are_off_by_default_and_local_when_on():
    assert StationConfig().metrics.port == 0 and AgentConfig().metrics.port == 0
    assert StationConfig().metrics.host == "127.0.0.1" == AgentConfig().metrics.host


async def test_each_daemon_serves_its_own_metrics(live_server, tenant: Tenant, tmp_path):
    ports = {"base": free_port(), "agent": free_port()}
    async with (
        platform(live_server.url, tenant, tmp_path, metrics_ports=ports) as p,
        httpx.AsyncClient() as c,
    ):

        async def scrape(daemon: str) -> str:
            r = await c.get(f"http://127.0.0.1:{ports[daemon]}/metrics")
            assert r.status_code == 200 and r.headers["content-type"].startswith("text/plain")
            return r.text

        async def acked(daemon: str) -> bool:
            return (
                value(await scrape(daemon), "aerobase_outbox_messages_total", outcome="acked") > 0
            )

        for daemon, expected in (("base", BASE), ("agent", AGENT)):
            await eventually(lambda d=daemon: acked(d), 20, f"the {daemon}'s acked messages")
            text = await scrape(daemon)
            names = {f.name for f in text_string_to_metric_families(text)}
            assert expected <= names, (daemon, expected - names)
            assert value(text, "aerobase_server_link_up") == 1
            assert value(text, "aerobase_outbox_depth") >= 0

        base = await scrape("base")
        assert value(base, "aerobase_plc_link_up") == 1
        assert value(base, "aerobase_plc_read_round_trip_seconds_count") > 0
        # a duration, not a bound: on a loaded machine the event loop adds its delay (1.98 s once)
        last = value(base, "aerobase_plc_read_round_trip_seconds_last")
        assert last > 0 and math.isfinite(last)
        assert value(base, "aerobase_rtk_state", state="streaming") == 1
        assert 0 <= value(base, "aerobase_rtk_correction_age_seconds") < 5.0  # else "stale"
        assert value(base, "aerobase_rtk_frames_total", outcome="good") > 0

        agent = await scrape("agent")
        assert value(agent, "aerobase_mavlink_link_up") == 1
        # the stream requests (SET_MESSAGE_INTERVAL) are commands answered by COMMAND_ACK
        assert value(agent, "aerobase_mavlink_command_round_trip_seconds_count") > 0
        assert value(agent, "aerobase_outbox_messages_total", outcome="sent") > 0
        assert p.agent.autopilot.round_trips.count > 0
    # stopped with its daemon: the port is free again
    async with httpx.AsyncClient() as c:
        for port in ports.values():
            with pytest.raises(httpx.ConnectError):
                await c.get(f"http://127.0.0.1:{port}/metrics", timeout=2)
