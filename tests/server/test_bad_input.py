"""Bad input over real HTTP gets a clear 4xx, never a 500 (issue 14, item 8).

A `.plan` with a bare NaN or 1e400, a cron expression that never fires, asset names that are not
safe file names; and the error encoder itself, which must never be what fails.
"""

from __future__ import annotations

import base64
import http.client
import json
import re
import uuid
from typing import Any
from urllib.parse import unquote, urlsplit

import httpx
import pytest

from assetlink.configfile import decrypt_config
from assetlink.link import Link
from protocol.telemetry_payloads import Position, UavTelemetry
from tests.conftest import SQUARE, Tenant


def _plan(lat: str = "47.397742", param3: str = "null", fence: str = "[]") -> str:
    """A one-waypoint .plan as text, so bare NaN and 1e400 reach the server as written."""
    return (
        '{"fileType": "Plan", "version": 1, "groundStation": "QGroundControl",'
        f' "geoFence": {{"circles": [], "polygons": {fence}, "version": 2}},'
        ' "mission": {"version": 2, "firmwareType": 3, "vehicleType": 2, "hoverSpeed": 5,'
        ' "plannedHomePosition": [47.397742, 8.545594, 488],'
        ' "items": [{"type": "SimpleItem", "command": 22, "frame": 3, "doJumpId": 1,'
        '   "params": [0, 0, 0, null, 47.397742, 8.545594, 20]},'
        '  {"type": "SimpleItem", "command": 16, "frame": 3, "doJumpId": 2,'
        f'   "params": [0, 0, 0, {param3}, {lat}, 8.546594, 20]}}]}}}}'
    )


class KeptAlive:
    """Two requests on one TCP connection (http.client), to see the first did not break it."""

    def __init__(self, base_url: str) -> None:
        u = urlsplit(base_url)
        self.conn = http.client.HTTPConnection(u.hostname or "", u.port, timeout=15)

    def request(
        self, method: str, path: str, body: str | None = None, headers: dict[str, str] | None = None
    ) -> tuple[int, dict[str, Any], http.client.HTTPResponse]:
        self.conn.request(method, path, body=body, headers=headers or {})
        r = self.conn.getresponse()
        data = r.read()
        return r.status, json.loads(data) if data else {}, r

    def close(self) -> None:
        self.conn.close()


@pytest.mark.parametrize(
    ("field", "plan", "token"),
    [
        ("params[3]", _plan(param3="NaN"), "NaN"),
        ("params[4] (latitude)", _plan(lat="1e400"), "Infinity"),
        ("params[4] (latitude)", _plan(lat="-Infinity"), "-Infinity"),
        ("params[4] (latitude)", _plan(lat="1" + "0" * 400), "an integer of 1329 bits"),
    ],
)
def test_plan_with_a_non_finite_number_is_422_naming_item_and_field(
    live_server, tenant: Tenant, field: str, plan: str, token: str
):
    """Before: 500 (the error body could not carry NaN) and the connection was reset after it."""
    client = KeptAlive(live_server.url)
    try:
        status, body, _ = client.request(
            "POST",
            "/api/v1/missions/import?name=nan",
            plan,
            {**tenant.h("operator"), "Content-Type": "application/json"},
        )
        assert status == 422, body
        error = body["error"]
        assert error["code"] == "import_rejected"
        assert error["message"].startswith(
            f"mission.items[1].{field.split()[0]}: item 1: {field} is not a finite number ("
        ), error["message"]
        assert error["details"][0]["index"] == 1 and error["details"][0]["command"] == 16
        assert error["details"][0]["value"] == token
        sock = client.conn.sock
        # the same connection still serves the next request
        status, health, _ = client.request("GET", "/api/health")
        assert status == 200 and client.conn.sock is sock, health
    finally:
        client.close()


def test_non_finite_numbers_outside_the_items_are_refused_not_stored(api, tenant: Tenant):
    """geoFence and rallyPoints are carried through untouched: a NaN there must not reach the database."""
    r = api.post(
        "/api/v1/missions/import",
        content=_plan(fence='[{"inclusion": true, "polygon": [[47.39, NaN], [47.4, 8.5]]}]'),
        headers={**tenant.h("operator"), "Content-Type": "application/json"},
    )
    assert r.status_code == 422, r.text
    assert r.json()["error"]["details"][0]["where"] == "geoFence.polygons[0].polygon[0][1]"
    assert api.get("/api/v1/missions", headers=tenant.h("viewer")).json() == []


def test_the_error_encoder_never_fails_on_non_finite_values():
    """Any details, however odd, render as strict JSON (non-finite numbers as their names)."""
    from server.kit.errors import ErrorResponse, error_body

    details = {
        "value": float("nan"),
        "limits": (float("inf"), -float("inf")),
        "nested": [[[{"x": float("nan")}]]],
        "deep": json.loads("[" * 200 + "]" * 200),
        "other": uuid.UUID(int=0),
    }
    raw = ErrorResponse(error_body("x", "y", details)).body
    decoded = json.loads(raw, parse_constant=lambda c: pytest.fail(f"{c} in the body"))
    assert decoded["error"]["details"]["value"] == "NaN"
    assert decoded["error"]["details"]["limits"] == ["Infinity", "-Infinity"]
    assert decoded["error"]["details"]["other"] == str(uuid.UUID(int=0))


def _schedule_body(tenant: Tenant, cron: str) -> dict[str, Any]:
    base = tenant.create_asset("landing_base")
    uav = tenant.create_asset("uav", base_id=base["id"])
    return {
        "name": "never",
        "mission_id": tenant.create_mission()["id"],
        "uav_id": uav["id"],
        "base_id": base["id"],
        "kind": "cron",
        "cron": cron,
        "timezone": "Europe/Lisbon",
    }


@pytest.mark.parametrize("cron", ["0 0 31 2 *", "0 0 30 2 *", "0 0 31 4,6,9,11 *"])
def test_a_cron_that_never_fires_is_422_naming_it(api, tenant: Tenant, cron: str):
    """Before: 500 (croniter's 'failed to find next date' escaped)."""
    r = api.post(
        "/api/v1/schedules", json=_schedule_body(tenant, cron), headers=tenant.h("operator")
    )
    assert r.status_code == 422, r.text
    assert r.json()["error"]["code"] == "invalid_schedule"
    assert (
        repr(cron) in r.json()["error"]["message"] and "never fires" in r.json()["error"]["message"]
    )


DISPOSITION = re.compile(r"""attachment; filename="([ -~]*)"(?:; filename\*=UTF-8''([!-~]+))?""")


@pytest.mark.parametrize(
    ("name", "expected"),
    [
        ("../../../etc/passwd", "etc_passwd"),
        ('evil"; filename=evil.sh', "evil_; filename=evil.sh"),
        ("Дрон Альфа", "Дрон Альфа"),
        ("base\u2028one", "base_one"),
        ("ドローン\\..\\x", "ドローン_.._x"),
    ],
)
def test_config_file_names_are_safe_in_content_disposition(
    api: httpx.Client, tenant: Tenant, name: str, expected: str
):
    """Before: the name went unescaped into the header (a non-Latin name made it a 500)."""
    suffix = f"-{uuid.uuid4().hex[:6]}"  # asset names are global
    asset = tenant.create_asset("landing_base", password="first-password-1", name=name + suffix)
    r = api.post(
        f"/api/v1/assets/{asset['id']}/config",
        json={"password": "second-password-2"},
        headers=tenant.h("admin"),
    )
    assert r.status_code == 200, r.text
    header = r.headers["content-disposition"]
    m = DISPOSITION.fullmatch(header)
    assert m, header
    fallback, encoded = m.groups()
    assert not set(fallback) & set('/\\"') and not fallback.startswith("."), fallback
    assert (unquote(encoded) if encoded else fallback) == f"{expected}{suffix}.abcf"
    assert decrypt_config(r.content, "second-password-2").name == name + suffix


@pytest.mark.parametrize(
    "attributes", ['{"x": NaN}', '{"a": {"b": [1, 1e400]}}', '{"x": "a\\u0000"}']
)
def test_asset_attributes_must_be_storable_json(api: httpx.Client, tenant: Tenant, attributes: str):
    """Before: 201 on SQLite (NaN sent back as null) and 500 on PostgreSQL (jsonb refuses NaN)."""
    body = (
        f'{{"name": "uav-{uuid.uuid4().hex[:8]}", "kind": "uav", '
        f'"password": "asset-password-123", "attributes": {attributes}}}'
    )
    r = api.post(
        "/api/v1/assets",
        content=body,
        headers={**tenant.h("admin"), "Content-Type": "application/json"},
    )
    assert r.status_code == 422, r.text
    assert r.json()["error"]["message"].startswith("invalid request: body.attributes:")


def test_after_a_500_the_client_is_told_to_reconnect(database_url: str):
    """An unhandled error still answers the envelope, with Connection: close: the server drops the
    connection after it, and on main a keep-alive client's next request met a closed socket."""
    from tests.conftest import LiveServer, test_settings

    server = LiveServer(test_settings(database_url))

    async def broken() -> None:
        raise RuntimeError("a bug")

    server.app.add_api_route("/api/test-broken", broken)
    server.start()
    client = KeptAlive(server.url)
    try:
        status, body, r = client.request("GET", "/api/test-broken")
        assert status == 500 and body["error"]["code"] == "internal_error"
        assert r.getheader("connection") == "close"
        status, _, _ = client.request("GET", "/api/health")  # http.client reconnects as told
        assert status == 200
    finally:
        client.close()
        server.stop()


@pytest.mark.parametrize("value", ["inf", "1e400", "-Infinity"])
def test_a_waypoint_file_with_an_infinite_number_names_the_line(api, tenant: Tenant, value: str):
    """WPL writes `nan` for "no value"; an infinite one is refused, saying what is allowed."""
    text = f"QGC WPL 110\n0\t1\t0\t16\t0\t0\t0\t0\t0\t0\t0\t1\n1\t0\t3\t16\t0\t0\t0\tnan\t{value}\t8.5\t20\t1\n"
    r = api.post(
        "/api/v1/missions/import",
        content=text,
        headers={**tenant.h("operator"), "Content-Type": "text/plain"},
    )
    assert r.status_code == 422, r.text
    assert r.json()["error"]["message"].startswith("line 3: fields must be finite numbers"), r.text


# found by a schema fuzz against the demo's data (ids that exist, with runs), each a 500 before


async def test_a_telemetry_bucket_below_a_millisecond_is_422(live_server, tenant: Tenant, tmp_path):
    """With samples stored, a bucket of 5e-324 s overflowed the downsampler (a 500)."""
    uav = tenant.create_asset("uav")
    cfg = decrypt_config(base64.b64decode(uav["config_file"]), "asset-password-123")
    link = Link(live_server.url, cfg.name, cfg.secret, tmp_path / "link.db", seed=1)
    await link.start()
    try:
        await link.wait_connected(15)
        for alt in (10.0, 20.0, 30.0):
            position = Position(lat=41.0, lon=-8.6, alt_msl_m=120.0, alt_rel_m=alt)
            await link.send_telemetry(UavTelemetry(position=position, armed=False))
        assert await link.flush(15)
    finally:
        await link.stop()
    path = f"/api/v1/assets/{uav['id']}/telemetry"
    always = {"start": "2000-01-01T00:00:00Z", "end": "2100-01-01T00:00:00Z"}
    async with httpx.AsyncClient(base_url=live_server.url, headers=tenant.h("viewer")) as c:
        r = await c.get(path, params={**always, "every": "5e-324"})
        assert r.status_code == 422 and "every" in r.json()["error"]["message"], r.text
        r = await c.get(path, params={**always, "every": 0.001, "fields": "position.alt_rel_m"})
    assert r.status_code == 200, r.text
    # a millisecond's buckets: each sample alone, or samples sent within one millisecond averaged
    means = [row["position.alt_rel_m"] for row in r.json()]
    assert 1 <= len(means) <= 3 and min(means) >= 10.0 and max(means) <= 30.0, means


def test_a_zone_patched_with_a_null_geometry_is_422(api: httpx.Client, tenant: Tenant):
    path = f"/api/v1/airspace/zones/{tenant.create_zone()['id']}"
    r = api.patch(path, json={"geometry": None, "radius_m": 30}, headers=tenant.h("operator"))
    assert r.status_code == 422 and r.json()["error"]["code"] == "invalid_zone", r.text
    assert api.get(path, headers=tenant.h("viewer")).json()["geometry"] == SQUARE


def test_an_asset_patched_with_nulls_keeps_those_fields_and_null_base_unbinds(
    api: httpx.Client, tenant: Tenant
):
    base = tenant.create_asset("landing_base")
    uav = tenant.create_asset("uav", base_id=base["id"], attributes={"mass_g": 1450})
    path = f"/api/v1/assets/{uav['id']}"
    nulls = {"name": None, "description": None, "attributes": None, "base_id": None}
    r = api.patch(path, json=nulls, headers=tenant.h("admin"))
    assert r.status_code == 200, r.text
    got = api.get(path, headers=tenant.h("viewer")).json()
    assert got["name"] == uav["name"] and got["attributes"] == {"mass_g": 1450}
    assert got["base_id"] is None


def test_an_asset_that_has_flown_a_run_is_409_on_delete_and_kept(api: httpx.Client, tenant: Tenant):
    base = tenant.create_asset("landing_base")
    uav = tenant.create_asset("uav", base_id=base["id"])
    ids = {"mission_id": tenant.create_mission()["id"], "uav_id": uav["id"], "base_id": base["id"]}
    run = api.post("/api/v1/runs", json=ids, headers=tenant.h("operator"))
    assert run.status_code == 201, run.text
    for asset in (uav, base):
        r = api.delete(f"/api/v1/assets/{asset['id']}", headers=tenant.h("admin"))
        assert r.status_code == 409 and r.json()["error"]["code"] == "asset_in_use", r.text
        assert "runs" in r.json()["error"]["message"]
        assert (
            api.get(f"/api/v1/assets/{asset['id']}", headers=tenant.h("viewer")).status_code == 200
        )
    # an asset that never flew is deleted as before
    spare = tenant.create_asset("uav")
    assert api.delete(f"/api/v1/assets/{spare['id']}", headers=tenant.h("admin")).status_code == 204
