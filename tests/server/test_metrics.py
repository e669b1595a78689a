"""`/metrics`: Prometheus text that prometheus-client's own parser reads, with every family the
operators' dashboards use, routes by template, and live connections counted."""

from __future__ import annotations

import base64
import uuid

import httpx
from prometheus_client.parser import text_string_to_metric_families

from assetlink.configfile import decrypt_config
from assetlink.link import Link
from tests.conftest import Tenant
from tests.metrics import value
from tests.polling import eventually

FAMILIES = {
    "aerobase_http_request_duration_seconds",
    "aerobase_commands",
    "aerobase_command_latency_seconds",
    "aerobase_runs",
    "aerobase_run_step_duration_seconds",
    "aerobase_run_lease_takeovers",
    "aerobase_ingest_lag_seconds",
    "aerobase_base_plc_link_up",
    "aerobase_base_rtk_corrections_per_second",
    "aerobase_base_rtk_correction_age_seconds",
    "aerobase_connected_assets",
    "aerobase_connected_operators",
    "aerobase_telemetry_messages_received",
    "aerobase_telemetry_messages_sent",
    "aerobase_logins",
}


def test_metrics_parse_and_carry_every_family(api):
    r = api.get("/metrics")
    assert r.status_code == 200
    assert r.headers["content-type"].startswith("text/plain")
    names = {f.name for f in text_string_to_metric_families(r.text)}
    assert FAMILIES <= names, FAMILIES - names


def test_http_latency_is_labelled_by_route_template_never_by_id(api, tenant: Tenant):
    run_id = uuid.uuid4()
    assert api.get(f"/api/v1/runs/{run_id}", headers=tenant.h("viewer")).status_code == 404
    text = api.get("/metrics").text
    assert str(run_id) not in text
    count = value(
        text,
        "aerobase_http_request_duration_seconds_count",
        method="GET",
        route="/api/v1/runs/{run_id}",
        status="404",
    )
    assert count >= 1


async def test_a_connected_asset_is_counted_while_its_socket_lives(
    live_server, tenant: Tenant, tmp_path
):
    asset = tenant.create_asset("uav")
    cfg = decrypt_config(base64.b64decode(asset["config_file"]), "asset-password-123")
    async with httpx.AsyncClient(base_url=live_server.url) as c:

        async def connected() -> float:
            return value((await c.get("/metrics")).text, "aerobase_connected_assets")

        before = await connected()
        link = Link(live_server.url, cfg.name, cfg.secret, tmp_path / "link.db", seed=1)
        await link.start()
        try:
            await link.wait_connected(20)
            assert await connected() == before + 1
        finally:
            await link.stop()

        async def gone() -> bool:
            return await connected() == before

        await eventually(gone, 10, "the asset's socket to be uncounted")
