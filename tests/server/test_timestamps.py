"""One timestamp format (issue 14 item 17): RFC 3339 UTC with `Z` in every REST body; any RFC 3339
offset accepted in requests and normalised; epoch milliseconds only in socket envelopes.

A realistic flow through every resource, over real HTTP and the asset's real socket; every JSON
body (answers, error details, the encrypted config file's body) is walked for timestamps."""

from __future__ import annotations

import asyncio
import base64
import re
from datetime import UTC, datetime, timedelta, timezone
from typing import Any

import httpx

from assetlink.configfile import decrypt_config
from protocol.messages import now_ms
from tests.conftest import LiveServer, Tenant, login
from tests.polling import wait_for
from tests.server.realtime_client import asset_socket, asset_token, message, next_of, uav_sample

# a date and a time anywhere in a string, with whatever follows it
STAMP = re.compile(r"\d{4}-\d{2}-\d{2}[T ]\d{2}:\d{2}(?::\d{2}(?:\.\d+)?)?(Z|[+-]\d{2}:?\d{2})?")


def stamps(value: Any, path: str = "$") -> list[tuple[str, str, str | None]]:
    """(where, text, zone) of every timestamp in a JSON value, in strings and keys alike."""
    found = []
    if isinstance(value, dict):
        for k, v in value.items():
            found += stamps(k, f"{path}.<key>") + stamps(v, f"{path}.{k}")
    elif isinstance(value, list):
        for i, v in enumerate(value):
            found += stamps(v, f"{path}[{i}]")
    elif isinstance(value, str):
        found += [(path, m.group(0), m.group(1)) for m in STAMP.finditer(value)]
    return found


class Recorder:
    """Every JSON body the flow reads, by request."""

    def __init__(self, api: httpx.Client) -> None:
        self.api = api
        self.bodies: list[tuple[str, Any]] = []

    def __call__(self, method: str, url: str, expect: int, **kw: Any) -> Any:
        r = self.api.request(method, url, **kw)
        assert r.status_code == expect, (method, url, r.status_code, r.text)
        if r.headers.get("content-type", "").startswith("application/json"):
            self.bodies.append((f"{method} {url} -> {r.status_code}", r.json()))
            return r.json()
        return r


def test_every_rest_body_of_a_realistic_flow_writes_times_as_utc_z(
    api: httpx.Client, live_server: LiveServer, tenant: Tenant
):
    """Before: `+00:00` in telemetry rows, the config file and 409 details; an offset given in a
    schedule's `at` came back as given (`+02:00`)."""
    call = Recorder(api)
    op, admin, viewer = tenant.h("operator"), tenant.h("admin"), tenant.h("viewer")

    # sessions: a login, who am I, a refused second login (its details carry times)
    call("GET", "/api/v1/auth/me", 200, headers=op)
    call(
        "POST",
        "/api/v1/auth/login",
        409,
        json={"email": tenant.emails["viewer"], "password": tenant.PASSWORD},
    )
    call("GET", "/api/v1/organizations", 200, headers=viewer)
    call("GET", f"/api/v1/organizations/{tenant.id}", 200, headers=viewer)
    users = call("GET", "/api/v1/users", 200, headers=viewer)
    call("PATCH", f"/api/v1/users/{users[-1]['id']}", 200, headers=admin, json={"role": "viewer"})

    # assets, and the configuration file inside the registration's answer
    base = call(
        "POST",
        "/api/v1/assets",
        201,
        headers=admin,
        json={"name": f"b-{tenant.name}", "kind": "landing_base", "password": "asset-password-123"},
    )
    uav = call(
        "POST",
        "/api/v1/assets",
        201,
        headers=admin,
        json={
            "name": f"u-{tenant.name}",
            "kind": "uav",
            "password": "asset-password-123",
            "base_id": base["id"],
        },
    )
    config = decrypt_config(base64.b64decode(uav["config_file"]), "asset-password-123")
    call.bodies.append(("config file", {"issued_at": config.issued_at}))
    call("GET", "/api/v1/assets", 200, headers=viewer)
    call("PATCH", f"/api/v1/assets/{uav['id']}", 200, headers=admin, json={"description": "X500"})

    # the UAV's link: telemetry and an event through the real socket
    async def fly() -> None:
        token = asset_token(live_server.url, uav)
        async with asset_socket(live_server.url, token) as ws:
            t0 = now_ms() - 5000
            for seq in range(1, 5):
                await ws.send(message("telemetry", uav_sample(seq), seq=seq, ts=t0 + seq * 1000))
            await ws.send(message("event", {"name": "landed", "message": "on the pad"}, seq=5))
            while (await next_of(ws, "ack"))["payload"]["seq"] < 5:
                pass

    asyncio.run(fly())
    telemetry = f"/api/v1/assets/{uav['id']}/telemetry"
    # a query time with another offset is taken as the same instant
    lisbon_summer = (datetime.now(UTC) - timedelta(minutes=10)).astimezone(
        timezone(timedelta(hours=1))
    )
    rows = call("GET", telemetry, 200, headers=viewer, params={"start": lisbon_summer.isoformat()})
    assert len(rows) == 4
    call(
        "GET",
        telemetry,
        200,
        headers=viewer,
        params={"every": 2, "start": lisbon_summer.isoformat()},
    )
    call("GET", f"{telemetry}/latest", 200, headers=viewer)
    call("GET", f"/api/v1/assets/{uav['id']}/events", 200, headers=viewer)

    # commands
    cmd = call(
        "POST",
        f"/api/v1/assets/{base['id']}/commands",
        202,
        headers=op,
        json={"name": "check_availability", "params": {}},
    )
    call("GET", f"/api/v1/assets/{base['id']}/commands", 200, headers=viewer)
    call("GET", f"/api/v1/commands/{cmd['id']}", 200, headers=viewer)

    # missions
    items = [{"command": 22, "lat": 41.178, "lon": -8.598, "alt": 20}, {"command": 20}]
    mission = call("POST", "/api/v1/missions", 201, headers=op, json={"name": "m", "items": items})
    call("PATCH", f"/api/v1/missions/{mission['id']}", 200, headers=op, json={"name": "m2"})
    call("GET", "/api/v1/missions", 200, headers=viewer)
    call(
        "POST",
        f"/api/v1/missions/{mission['id']}/validate",
        200,
        headers=op,
        json={"uav_id": uav["id"]},
    )

    # a run (the base never answers: it is aborted), its report and the fleet report
    run = call(
        "POST",
        "/api/v1/runs",
        201,
        headers=op,
        json={"mission_id": mission["id"], "uav_id": uav["id"], "base_id": base["id"]},
    )
    call("POST", f"/api/v1/runs/{run['id']}/abort", 202, headers=op, json={"reason": "test"})
    wait_for(
        lambda: api.get(f"/api/v1/runs/{run['id']}", headers=viewer).json()["finished_at"],
        60,
        what="the run to end",
    )
    call("GET", f"/api/v1/runs/{run['id']}", 200, headers=viewer)
    call("GET", f"/api/v1/runs/{run['id']}/report", 200, headers=viewer)
    call("GET", "/api/v1/runs", 200, headers=viewer)
    call(
        "GET",
        "/api/v1/reports/fleet",
        200,
        headers=viewer,
        params={"start": "2026-01-01T00:00:00+05:30"},
    )

    # schedules: `at` given at +02:00 comes back as the same instant in UTC
    at = datetime.now(UTC).replace(microsecond=0) + timedelta(days=2)
    given = at.astimezone(timezone(timedelta(hours=2))).isoformat()
    assert given.endswith("+02:00")
    once = call(
        "POST",
        "/api/v1/schedules",
        201,
        headers=op,
        json={
            "name": "later",
            "mission_id": mission["id"],
            "uav_id": uav["id"],
            "base_id": base["id"],
            "kind": "once",
            "at": given,
        },
    )
    assert once["at"] == at.strftime("%Y-%m-%dT%H:%M:%SZ") == once["next_due_at"]
    # a schedule due now whose UAV is busy: its last_result names the due time
    busy = call(
        "POST",
        "/api/v1/runs",
        201,
        headers=op,
        json={"mission_id": mission["id"], "uav_id": uav["id"], "base_id": base["id"]},
    )
    soon = (datetime.now(UTC) + timedelta(seconds=1)).isoformat()
    fired = call(
        "POST",
        "/api/v1/schedules",
        201,
        headers=op,
        json={
            "name": "now",
            "mission_id": mission["id"],
            "uav_id": uav["id"],
            "base_id": base["id"],
            "kind": "once",
            "at": soon,
        },
    )
    wait_for(
        lambda: api.get(f"/api/v1/schedules/{fired['id']}", headers=viewer).json()["last_result"],
        30,
        what="the schedule to fire",
    )
    result = call("GET", f"/api/v1/schedules/{fired['id']}", 200, headers=viewer)["last_result"]
    assert "could not start the run due" in result or busy["id"] in result, result
    call("GET", "/api/v1/schedules", 200, headers=viewer)
    call("PATCH", f"/api/v1/schedules/{once['id']}", 200, headers=op, json={"enabled": False})
    call("GET", "/api/v1/audit", 200, headers=admin)

    seen = [
        (where, body_where, text, zone)
        for where, body in call.bodies
        for body_where, text, zone in stamps(body)
    ]
    kinds = {
        where.split(" -> ")[0].split(" ")[-1].split("/")[3]
        for where, *_ in seen
        if where != "config file"
    }
    assert len(seen) > 100 and len(kinds) >= 9, kinds  # the walk did see times everywhere
    wrong = [s for s in seen if s[3] != "Z"]
    assert wrong == [], wrong[:10]


def test_a_time_without_an_offset_is_refused_not_guessed(api: httpx.Client, tenant: Tenant):
    """RFC 3339 needs an offset: a bare local time in a body or a query is a 422 naming it."""
    uav = tenant.create_asset("uav")
    r = api.get(
        f"/api/v1/assets/{uav['id']}/telemetry",
        params={"start": "2026-11-22T10:00:00"},
        headers=tenant.h("viewer"),
    )
    assert r.status_code == 422, r.text
    assert r.json()["error"]["details"][0]["loc"] == ["query", "start"]
    assert "time zone offset" in r.json()["error"]["details"][0]["msg"]
    r = api.get("/api/v1/reports/fleet", params={"end": "2026-11-22 10:00"}, headers=tenant.h())
    assert r.status_code == 422


def test_the_token_answer_and_me_use_z(api: httpx.Client, tenant: Tenant):
    token = login(api, tenant.emails["viewer"], tenant.PASSWORD, force=True)
    me = api.get("/api/v1/auth/me", headers={"Authorization": f"Bearer {token}"}).json()
    assert me["session_expires_at"].endswith("Z") and "+" not in me["session_expires_at"]


def test_every_time_in_the_openapi_document_is_the_shared_type(api: httpx.Client):
    """Every `date-time` the API declares, in or out, is `Timestamp` (server/kit/types.py):
    one place decides the format."""
    doc = api.get("/api/openapi.json").json()
    found: list[str] = []

    def walk(node: Any, where: str) -> None:
        if isinstance(node, dict):
            if node.get("format") == "date-time":
                found.append(where)
                assert node.get("description", "").startswith("RFC 3339"), where
            for k, v in node.items():
                walk(v, f"{where}.{k}")
        elif isinstance(node, list):
            for i, v in enumerate(node):
                walk(v, f"{where}[{i}]")

    walk(doc, "$")
    assert len(found) >= 25, found
