"""ETag / If-Match on what operators edit (issue 14 item 17): missions, schedules, users, assets.
A stale edit is refused with 412 instead of silently overwriting another operator's. Real HTTP."""

from __future__ import annotations

import asyncio
from typing import Any

import httpx
import pytest

from tests.conftest import LiveServer, Tenant


def _mission(api: httpx.Client, tenant: Tenant, name: str = "fence") -> httpx.Response:
    r = api.post(
        "/api/v1/missions",
        headers=tenant.h("operator"),
        json={"name": name, "items": [{"command": 22, "lat": 41.178, "lon": -8.598, "alt": 20}]},
    )
    assert r.status_code == 201, r.text
    return r


def _strong(r: httpx.Response) -> str:
    tag = r.headers["etag"]
    assert tag.startswith('"') and tag.endswith('"'), tag  # strong: no W/
    return tag


def test_two_operators_editing_one_mission_the_second_gets_412(api: httpx.Client, tenant: Tenant):
    """Before: both PATCHes answered 200 and the first operator's edit was silently lost."""
    created = _mission(api, tenant)
    url = f"/api/v1/missions/{created.json()['id']}"
    first, second = tenant.h("operator"), tenant.h("admin")  # two people, two sessions
    seen_a = api.get(url, headers=first)
    seen_b = api.get(url, headers=second)
    assert _strong(seen_a) == _strong(seen_b) == _strong(created)

    a = api.patch(url, json={"name": "north fence"}, headers={**first, "If-Match": _strong(seen_a)})
    assert a.status_code == 200, a.text
    assert _strong(a) != _strong(seen_a)
    assert _strong(api.get(url, headers=first)) == _strong(a)  # the answer's tag is the new one

    b = api.patch(
        url, json={"name": "south fence"}, headers={**second, "If-Match": _strong(seen_b)}
    )
    assert b.status_code == 412, b.text
    err = b.json()["error"]
    assert err["code"] == "precondition_failed" and "changed since it was read" in err["message"]
    assert err["details"]["current_etag"] == _strong(a)
    assert api.get(url, headers=first).json()["name"] == "north fence"  # B changed nothing

    # B reads again and reapplies its edit on the new version
    again = api.get(url, headers=second)
    retry = api.patch(
        url, json={"name": "south fence"}, headers={**second, "If-Match": _strong(again)}
    )
    assert retry.status_code == 200 and retry.json()["name"] == "south fence"


def test_simultaneous_edits_with_the_same_tag_exactly_one_wins(
    live_server: LiveServer, api: httpx.Client, tenant: Tenant
):
    """Eight PATCHes sent at once, each based on the same version: one 200, seven 412."""
    created = _mission(api, tenant)
    url = f"{live_server.url}/api/v1/missions/{created.json()['id']}"
    tag = _strong(created)

    async def race() -> list[httpx.Response]:
        async with httpx.AsyncClient(timeout=30) as client:
            return list(
                await asyncio.gather(
                    *(
                        client.patch(
                            url,
                            json={"name": f"edit {i}"},
                            headers={**tenant.h("operator"), "If-Match": tag},
                        )
                        for i in range(8)
                    )
                )
            )

    answers = asyncio.run(race())
    codes = sorted(r.status_code for r in answers)
    assert codes == [200] + [412] * 7, [r.text for r in answers]
    winner = next(r for r in answers if r.status_code == 200)
    stored = api.get(url, headers=tenant.h("viewer"))
    assert stored.json()["name"] == winner.json()["name"]
    assert _strong(stored) == _strong(winner)
    for r in answers:
        if r.status_code == 412:
            assert r.json()["error"]["code"] == "precondition_failed"


def test_simultaneous_edits_without_if_match_never_fail_the_server(
    live_server: LiveServer, api: httpx.Client, tenant: Tenant
):
    """Without If-Match an edit applies to the current version: each one is applied or, when it
    lost a race the database saw (no row lock on SQLite), refused with 409 edit_conflict."""
    created = _mission(api, tenant)
    url = f"{live_server.url}/api/v1/missions/{created.json()['id']}"

    async def race() -> list[httpx.Response]:
        async with httpx.AsyncClient(timeout=30) as client:
            return list(
                await asyncio.gather(
                    *(
                        client.patch(url, json={"name": f"e{i}"}, headers=tenant.h("operator"))
                        for i in range(6)
                    )
                )
            )

    answers = asyncio.run(race())
    assert {r.status_code for r in answers} <= {200, 409}, [r.text for r in answers]
    assert any(r.status_code == 200 for r in answers)
    for r in answers:
        if r.status_code == 409:
            assert r.json()["error"]["code"] == "edit_conflict"
    version = int(_strong(api.get(url, headers=tenant.h("viewer"))).strip('"'))
    assert version == 1 + sum(r.status_code == 200 for r in answers)  # each applied edit counted


@pytest.mark.parametrize(
    ("if_match", "status"),
    [
        (None, 200),  # no precondition: the edit proceeds
        ("*", 200),  # any version
        ('"999", CURRENT', 200),  # a list naming the current one
        ("W/CURRENT", 412),  # a weak tag never matches strongly (RFC 9110 13.1.1)
        ('"999"', 412),
        ("CURRENT-unquoted", 400),  # not an entity tag
    ],
)
def test_if_match_forms(api: httpx.Client, tenant: Tenant, if_match: str | None, status: int):
    created = _mission(api, tenant)
    url = f"/api/v1/missions/{created.json()['id']}"
    headers = dict(tenant.h("operator"))
    if if_match is not None:
        current = _strong(created)
        value = if_match.replace("CURRENT-unquoted", current.strip('"'))
        headers["If-Match"] = value.replace("CURRENT", current)
    r = api.patch(url, json={"description": "x"}, headers=headers)
    assert r.status_code == status, r.text
    if status != 200:
        assert r.json()["error"]["code"] == {412: "precondition_failed", 400: "bad_request"}[status]


def test_delete_with_a_stale_tag_is_refused_and_deletes_nothing(api: httpx.Client, tenant: Tenant):
    created = _mission(api, tenant)
    url = f"/api/v1/missions/{created.json()['id']}"
    stale = _strong(created)
    assert api.patch(url, json={"name": "renamed"}, headers=tenant.h("operator")).status_code == 200
    r = api.delete(url, headers={**tenant.h("operator"), "If-Match": stale})
    assert r.status_code == 412 and r.json()["error"]["code"] == "precondition_failed"
    current = api.get(url, headers=tenant.h("viewer"))
    assert current.status_code == 200
    r = api.delete(url, headers={**tenant.h("operator"), "If-Match": _strong(current)})
    assert r.status_code == 204
    assert api.get(url, headers=tenant.h("viewer")).status_code == 404


def _schedule(api: httpx.Client, tenant: Tenant) -> httpx.Response:
    base = tenant.create_asset("landing_base")
    uav = tenant.create_asset("uav", base_id=base["id"])
    mission = _mission(api, tenant).json()
    r = api.post(
        "/api/v1/schedules",
        headers=tenant.h("operator"),
        json={
            "name": "dawn",
            "mission_id": mission["id"],
            "uav_id": uav["id"],
            "base_id": base["id"],
            "kind": "cron",
            "cron": "0 6 * * *",
            "enabled": False,
        },
    )
    assert r.status_code == 201, r.text
    return r


def _stale_edit_refused(
    api: httpx.Client,
    url: str,
    created: httpx.Response,
    edit: dict[str, Any],
    other: dict[str, Any],
    h: dict[str, str],
) -> None:
    """GET's tag is POST's; an edit moves it; an edit based on the old tag is 412."""
    seen = api.get(url, headers=h)
    assert seen.status_code == 200, seen.text
    assert _strong(seen) == _strong(created)
    changed = api.patch(url, json=edit, headers={**h, "If-Match": _strong(seen)})
    assert changed.status_code == 200, changed.text
    assert _strong(changed) != _strong(seen) and _strong(api.get(url, headers=h)) == _strong(
        changed
    )
    stale = api.patch(url, json=other, headers={**h, "If-Match": _strong(seen)})
    assert stale.status_code == 412, stale.text
    assert stale.json()["error"]["code"] == "precondition_failed"
    assert api.delete(url, headers={**h, "If-Match": _strong(seen)}).status_code == 412


def test_schedules_users_and_assets_carry_etags_and_refuse_stale_edits(
    api: httpx.Client, tenant: Tenant
):
    created = _schedule(api, tenant)
    _stale_edit_refused(
        api,
        f"/api/v1/schedules/{created.json()['id']}",
        created,
        {"name": "dusk"},
        {"enabled": True},
        tenant.h("operator"),
    )

    r = api.post(
        "/api/v1/users",
        json={"email": f"new-{tenant.name}@example.com", "password": "x" * 12, "role": "viewer"},
        headers=tenant.h("admin"),
    )
    assert r.status_code == 201, r.text
    _stale_edit_refused(
        api,
        f"/api/v1/users/{r.json()['id']}",
        r,
        {"role": "operator"},
        {"is_active": False},
        tenant.h("admin"),
    )

    body = {"name": f"uav-{tenant.name}", "kind": "uav", "password": "asset-password-123"}
    r = api.post("/api/v1/assets", json=body, headers=tenant.h("admin"))
    assert r.status_code == 201, r.text
    _stale_edit_refused(
        api,
        f"/api/v1/assets/{r.json()['id']}",
        r,
        {"description": "X500"},
        {"attributes": {"mass_g": 1}},
        tenant.h("admin"),
    )


def test_deleting_a_base_gives_its_uavs_a_new_tag(api: httpx.Client, tenant: Tenant):
    """The UAV's `base_id` becomes null: its representation changed, so must its ETag."""
    base = tenant.create_asset("landing_base")
    uav = tenant.create_asset("uav", base_id=base["id"])
    url = f"/api/v1/assets/{uav['id']}"
    before = _strong(api.get(url, headers=tenant.h()))
    assert api.delete(f"/api/v1/assets/{base['id']}", headers=tenant.h()).status_code == 204
    after = api.get(url, headers=tenant.h())
    assert after.json()["base_id"] is None and _strong(after) != before


def test_the_openapi_document_declares_the_tag_and_the_412(api: httpx.Client):
    doc = api.get("/api/openapi.json").json()
    for path in (
        "/api/v1/missions/{mission_id}",
        "/api/v1/schedules/{schedule_id}",
        "/api/v1/users/{user_id}",
        "/api/v1/assets/{asset_id}",
    ):
        ops = doc["paths"][path]
        assert "ETag" in ops["get"]["responses"]["200"]["headers"], path
        assert "ETag" in ops["patch"]["responses"]["200"]["headers"], path
        for method in ("patch", "delete"):
            assert "412" in ops[method]["responses"], (path, method)
            names = {p["name"] for p in ops[method]["parameters"] if p["in"] == "header"}
            assert "If-Match" in names, (path, method)
