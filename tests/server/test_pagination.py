"""Pages with totals on every list endpoint (issue 14 item 17): `limit`/`offset` in, the body a
JSON array, `X-Total-Count` and an RFC 8288 `Link` (next/prev, same filters) out. Real HTTP."""

from __future__ import annotations

import asyncio
import re
import uuid
from collections.abc import Iterator
from typing import Any
from urllib.parse import parse_qs, urlsplit

import httpx
import pytest

from protocol.messages import now_ms
from tests.conftest import SUPERUSER_PASSWORD, LiveServer, Tenant, login, test_settings
from tests.server.realtime_client import asset_socket, asset_token, message, next_of

TOTAL_HEADER = "X-Total-Count"
LINK = re.compile(r'<([^>]*)>\s*;\s*rel="([^"]+)"')
# time series, paged by time (`start`/`end`), not by offset: see frontend_api.md
NOT_PAGED = {"/api/v1/assets/{asset_id}/telemetry"}


def links(r: httpx.Response) -> dict[str, str]:
    """The Link header's targets by relation."""
    return {rel: url for url, rel in LINK.findall(r.headers.get("link", ""))}


def walk(api: httpx.Client, path: str, headers: dict[str, str], **params: Any) -> list[Any]:
    """Every row of a list, by following rel="next" from the first page; checks each page."""
    r = api.get(path, params=params, headers=headers)
    assert r.status_code == 200, r.text
    total = int(r.headers[TOTAL_HEADER])
    rows: list[Any] = list(r.json())
    assert "prev" not in links(r)
    pages = 1
    while "next" in links(r):
        target = links(r)["next"]
        assert target.startswith(path + "?"), target  # relative, same path
        query = parse_qs(urlsplit(target).query)
        for name, value in params.items():  # the filters travel with the link
            if name != "offset":
                assert query[name] == [str(value)], (name, target)
        r = api.get(target, headers=headers)
        assert r.status_code == 200, r.text
        assert int(r.headers[TOTAL_HEADER]) == total
        assert "prev" in links(r)
        rows += r.json()
        pages += 1
    assert len(rows) == total, (path, len(rows), total)
    if "limit" in params:
        assert pages == max(1, -(-total // int(params["limit"])))
    return rows


def ids(rows: list[Any]) -> list[str]:
    ids_ = [row["id"] for row in rows]
    assert len(set(ids_)) == len(ids_), "a row was on two pages"
    return ids_


def test_every_list_in_the_openapi_document_is_paged(api: httpx.Client):
    """Every GET answering a JSON array takes limit and offset and declares the two headers."""
    doc = api.get("/api/openapi.json").json()
    lists = []
    for path, ops in doc["paths"].items():
        op = ops.get("get")
        ok = (op or {}).get("responses", {}).get("200", {})
        schema = ok.get("content", {}).get("application/json", {}).get("schema", {})
        if schema.get("type") != "array" or path in NOT_PAGED:
            continue
        lists.append(path)
        query = {p["name"] for p in op["parameters"] if p["in"] == "query"}
        assert {"limit", "offset"} <= query, path
        assert {TOTAL_HEADER, "Link"} <= set(ok.get("headers", {})), path
    assert len(lists) >= 9, lists  # organisations, users, assets, audit, commands, events, ...+3


@pytest.mark.parametrize(
    "path",
    [
        "/api/v1/missions",
        "/api/v1/assets",
        "/api/v1/users",
        "/api/v1/organizations",
        "/api/v1/runs",
        "/api/v1/schedules",
        "/api/v1/audit",
    ],
)
@pytest.mark.parametrize(
    "query", [{"limit": 0}, {"limit": 1001}, {"offset": -1}, {"limit": "x"}, {"offset": 10**10}]
)
def test_page_bounds_are_checked(api: httpx.Client, tenant: Tenant, path: str, query: dict):
    r = api.get(path, params=query, headers=tenant.h("admin"))
    assert r.status_code == 422, r.text
    assert r.json()["error"]["code"] == "validation_error"
    assert r.json()["error"]["details"][0]["loc"][:2] == ["query", next(iter(query))]


def test_missions_assets_and_schedules_page_with_totals_and_filters(
    api: httpx.Client, tenant: Tenant
):
    """Before: no total anywhere, so a front-end could not draw a pager."""
    made = [tenant.create_mission(f"m{i}")["id"] for i in range(5)]
    h = tenant.h("viewer")
    assert ids(walk(api, "/api/v1/missions", h, limit=2)) == made  # oldest first, no gaps
    assert walk(api, "/api/v1/missions", h, limit=2, kind="survey") == []
    assert len(walk(api, "/api/v1/missions", h, limit=3, kind="waypoints")) == 5

    bases = [tenant.create_asset("landing_base")["id"] for _ in range(3)]
    uavs = [tenant.create_asset("uav", base_id=b)["id"] for b in bases[:2]]
    assert ids(walk(api, "/api/v1/assets", h, limit=2, kind="landing_base")) == bases
    assert ids(walk(api, "/api/v1/assets", h, limit=1)) == bases + uavs

    for i in range(3):
        r = api.post(
            "/api/v1/schedules",
            headers=tenant.h("operator"),
            json={
                "name": f"s{i}",
                "mission_id": made[0],
                "uav_id": uavs[0],
                "base_id": bases[0],
                "kind": "interval",
                "interval_s": 3600,
                "enabled": False,
            },
        )
        assert r.status_code == 201, r.text
    assert len(ids(walk(api, "/api/v1/schedules", h, limit=2))) == 3

    runs = []
    for uav, base in zip(uavs, bases, strict=False):
        r = api.post(
            "/api/v1/runs",
            headers=tenant.h("operator"),
            json={"mission_id": made[0], "uav_id": uav, "base_id": base},
        )
        assert r.status_code == 201, r.text
        runs.append(r.json()["id"])
    assert ids(walk(api, "/api/v1/runs", h, limit=1)) == runs[::-1]  # newest first
    assert ids(walk(api, "/api/v1/runs", h, limit=1, uav_id=uavs[1])) == [runs[1]]


def test_an_offset_past_the_end_is_empty_with_the_total_and_a_way_back(
    api: httpx.Client, tenant: Tenant
):
    for i in range(3):
        tenant.create_mission(f"m{i}")
    r = api.get("/api/v1/missions", params={"limit": 2, "offset": 50}, headers=tenant.h())
    assert r.status_code == 200 and r.json() == []
    assert r.headers[TOTAL_HEADER] == "3"
    assert "next" not in links(r)
    back = api.get(links(r)["prev"], headers=tenant.h())
    assert [m["name"] for m in back.json()] == ["m1", "m2"]  # the last page
    # no rows at all: total 0, no links
    empty = api.get("/api/v1/missions", params={"kind": "survey"}, headers=tenant.h())
    assert empty.headers[TOTAL_HEADER] == "0" and "link" not in empty.headers


def test_users_organizations_and_the_audit_log_are_paged(
    api: httpx.Client, tenant: Tenant, superuser_email: str
):
    rows = walk(api, "/api/v1/users", tenant.h("viewer"), limit=2)
    assert {u["id"] for u in rows} >= set(tenant.user_ids.values())
    # one's own organisation only: a total of 1, whatever the page
    assert ids(walk(api, "/api/v1/organizations", tenant.h("viewer"), limit=1)) == [tenant.id]
    r = api.get("/api/v1/organizations", params={"offset": 1}, headers=tenant.h("viewer"))
    assert r.json() == [] and r.headers[TOTAL_HEADER] == "1"
    # a superuser sees every organisation: the total counts them all
    root = login(api, superuser_email, SUPERUSER_PASSWORD, force=True)
    every = walk(api, "/api/v1/organizations", {"Authorization": f"Bearer {root}"}, limit=7)
    assert tenant.id in ids(every)
    logins = walk(api, "/api/v1/audit", tenant.h("admin"), limit=1, action="login")
    assert len(logins) >= 3 and {e["action"] for e in logins} == {"login"}


def test_commands_and_events_of_an_asset_are_paged(
    api: httpx.Client, live_server: LiveServer, tenant: Tenant
):
    uav = tenant.create_asset("uav")
    path = f"/api/v1/assets/{uav['id']}/commands"
    sent = []
    for _ in range(3):
        r = api.post(
            path, headers=tenant.h("operator"), json={"name": "check_availability", "params": {}}
        )
        assert r.status_code == 202, r.text
        sent.append(r.json()["id"])
    assert ids(walk(api, path, tenant.h("viewer"), limit=2)) == sent[::-1]  # newest first
    r = api.get(path, params={"limit": 501}, headers=tenant.h("viewer"))
    assert r.status_code == 422  # this list's own maximum

    async def send_events() -> None:
        token = asset_token(live_server.url, uav)
        async with asset_socket(live_server.url, token) as ws:
            for seq in range(1, 6):
                payload = {"name": "waypoint_reached", "message": str(seq), "data": {"index": seq}}
                await ws.send(message("event", payload, seq=seq, ts=now_ms() - 1000 + seq))
            while (await next_of(ws, "ack"))["payload"]["seq"] < 5:  # stored once acked
                pass

    asyncio.run(send_events())
    events = walk(api, f"/api/v1/assets/{uav['id']}/events", tenant.h("viewer"), limit=2)
    assert [e["message"] for e in events] == ["1", "2", "3", "4", "5"]


def test_events_of_the_same_millisecond_keep_the_order_they_were_sent(
    api: httpx.Client, live_server: LiveServer, tenant: Tenant
):
    """An agent reports `armed` and `took_off` from one state, stamped alike: the list keeps the
    order they came in (was: by their random ids, so `took_off, armed` half the time)."""
    uav = tenant.create_asset("uav")
    names = ["armed", "took_off", "waypoint_reached", "mission_finished", "landing", "landed"]

    async def send_events() -> None:
        token = asset_token(live_server.url, uav)
        ts = now_ms() - 1000
        async with asset_socket(live_server.url, token) as ws:
            for seq, name in enumerate(names, start=1):
                await ws.send(message("event", {"name": name}, seq=seq, ts=ts))
            while (await next_of(ws, "ack"))["payload"]["seq"] < len(names):
                pass

    asyncio.run(send_events())
    events = walk(api, f"/api/v1/assets/{uav['id']}/events", tenant.h("viewer"), limit=4)
    assert [e["name"] for e in events] == names
    assert len({e["ts"] for e in events}) == 1


@pytest.fixture(scope="module")
def cors_server(database_url: str) -> Iterator[LiveServer]:
    server = LiveServer(test_settings(database_url, cors_origins=["https://ops.example.com"]))
    server.start()
    yield server
    server.stop()


def test_a_browser_may_read_the_total_and_the_links(cors_server: LiveServer):
    r = httpx.get(
        f"{cors_server.url}/api/v1/missions", headers={"Origin": "https://ops.example.com"}
    )
    exposed = {h.strip().lower() for h in r.headers["access-control-expose-headers"].split(",")}
    assert {"x-total-count", "link"} <= exposed


def test_the_link_keeps_a_repeated_filter_and_drops_nothing(api: httpx.Client, tenant: Tenant):
    """Filters are copied as given (here an unknown-to-paging `kind`), only limit/offset change."""
    for i in range(3):
        tenant.create_mission(f"k{i}-{uuid.uuid4().hex[:4]}")
    r = api.get(
        "/api/v1/missions",
        params={"kind": "waypoints", "limit": 1, "offset": 1},
        headers=tenant.h(),
    )
    nxt, prev = links(r)["next"], links(r)["prev"]
    assert parse_qs(urlsplit(nxt).query) == {"kind": ["waypoints"], "limit": ["1"], "offset": ["2"]}
    assert parse_qs(urlsplit(prev).query) == {
        "kind": ["waypoints"],
        "limit": ["1"],
        "offset": ["0"],
    }
