"""Walks EVERY route of the OpenAPI document with tokens of three organisations and every role.

Proves: no cross-organisation read or write (another organisation's resource is 404, never 2xx,
and its ids never appear in a response), a viewer cannot write, an operator cannot manage users
or assets' credentials. A route added later is walked too; a path parameter the walk does not know
how to fill fails the test, so nobody can add a route that escapes it.
"""

from __future__ import annotations

import re
import uuid
from typing import Any

import pytest

from tests.conftest import Tenant

PUBLIC = {
    ("POST", "/api/v1/auth/login"),
    ("POST", "/api/v1/assets/login"),
    ("GET", "/api/health"),
    ("GET", "/api/ready"),
}
# Routes every role may call on its own session (not organisation data).
SELF = {
    ("POST", "/api/v1/auth/logout"),
    ("POST", "/api/v1/auth/renew"),
    ("GET", "/api/v1/auth/me"),
    ("POST", "/api/v1/auth/password"),
}
# Management of users and of assets' credentials: admins only.
ADMIN_ONLY = [
    (r"POST|PATCH|DELETE", r"^/api/v1/users"),
    (r"POST|PATCH|DELETE", r"^/api/v1/assets(/\{asset_id\})?$"),
    (r"POST", r"/config$"),
    (r"GET", r"^/api/v1/audit"),
]
SUPERUSER_ONLY = [(r"POST", r"^/api/v1/organizations$")]
# Watching video is a viewer's right (WHEP: open, trickle, close a viewer session)
VIEWER_WRITES = [(r"POST|PATCH|DELETE", r"/video/whep")]


def _matches(rules: list[tuple[str, str]], method: str, path: str) -> bool:
    return any(re.fullmatch(m, method) and re.search(p, path) for m, p in rules)


def _example(schema: dict[str, Any], spec: dict[str, Any]) -> Any:
    """A minimal valid instance of a JSON schema (enough to get past validation)."""
    if "$ref" in schema:
        name = schema["$ref"].rsplit("/", 1)[-1]
        return _example(spec["components"]["schemas"][name], spec)
    for key in ("anyOf", "oneOf", "allOf"):
        if key in schema:
            options = [s for s in schema[key] if s.get("type") != "null"]
            return _example(options[0], spec)
    if "enum" in schema:
        return schema["enum"][0]
    if "default" in schema:
        return schema["default"]
    kind = schema.get("type")
    if kind == "object":
        return {
            k: _example(v, spec)
            for k, v in schema.get("properties", {}).items()
            if k in schema.get("required", [])
        }
    if kind == "array":
        return []
    if kind in ("integer", "number"):
        return schema.get("minimum", 1)
    if kind == "boolean":
        return False
    if schema.get("format") == "uuid":
        return str(uuid.uuid4())
    if schema.get("format") == "date-time":
        return "2026-01-01T00:00:00Z"
    n = max(schema.get("minLength", 1), 12)
    if "mail" in str(schema.get("title", "")).lower():
        return f"walk-{uuid.uuid4().hex[:8]}@walk.test"
    return f"walk-{uuid.uuid4().hex}"[: max(n, 16)]


class Victim:
    """Org A's resources whose ids fill the path parameters."""

    def __init__(self, tenant: Tenant) -> None:
        self.tenant = tenant
        base = tenant.create_asset("landing_base")
        uav = tenant.create_asset("uav", base_id=base["id"])["id"]
        cmd = tenant.api.post(
            f"/api/v1/assets/{uav}/commands",
            json={"name": "check_availability"},
            headers=tenant.h("operator"),
        )
        assert cmd.status_code == 202, cmd.text
        mission = tenant.create_mission("walk-mission")
        ids = {"mission_id": mission["id"], "uav_id": uav, "base_id": base["id"]}
        run = tenant.api.post("/api/v1/runs", headers=tenant.h("operator"), json=ids)
        assert run.status_code == 201, run.text
        schedule = tenant.api.post(
            "/api/v1/schedules",
            headers=tenant.h("operator"),
            json={
                **ids,
                "name": "walk-schedule",
                "kind": "cron",
                "cron": "0 6 * * *",
                "timezone": "Europe/Lisbon",
            },
        )
        assert schedule.status_code == 201, schedule.text
        zone = tenant.create_zone(
            "walk-zone", geometry={"type": "Point", "coordinates": [8.6, 47.4]}, radius_m=50
        )
        self.ids = {
            "zone_id": zone["id"],
            "run_id": run.json()["id"],
            "schedule_id": schedule.json()["id"],
            "asset_id": uav,
            "command_id": cmd.json()["id"],
            "user_id": tenant.user_ids["viewer"],
            "organization_id": tenant.id,
            "mission_id": mission["id"],
            "session_id": str(uuid.uuid4()),  # a video session (none exists: 404 past the checks)
            "name": "20260101T000000.000000Z.webm",  # a recording (none exists)
        }
        self.secret_values = set(self.ids.values()) | {tenant.name}

    def fill(self, path: str) -> str:
        def sub(m: re.Match[str]) -> str:
            name = m.group(1)
            if name not in self.ids:
                pytest.fail(
                    f"route {path}: the authorization walk does not know how to fill {{{name}}}; "
                    "add a resource of that kind to Victim"
                )
            return self.ids[name]

        return re.sub(r"\{(\w+)\}", sub, path)


def _operations(spec: dict[str, Any]) -> list[tuple[str, str, dict[str, Any]]]:
    ops = []
    for path, item in spec["paths"].items():
        for method, op in item.items():
            if method in ("get", "post", "put", "patch", "delete"):
                ops.append((method.upper(), path, op))
    return ops


def _body(op: dict[str, Any], spec: dict[str, Any]) -> Any:
    content = op.get("requestBody", {}).get("content", {})
    if "application/json" in content:
        body = _example(content["application/json"]["schema"], spec)
        if isinstance(body, dict) and "email" in body:
            body["email"] = f"walk-{uuid.uuid4().hex[:8]}@walk.test"
        if isinstance(body, dict) and "name" in body:
            body["name"] = f"walk-{uuid.uuid4().hex[:10]}"
        return body
    return None


@pytest.mark.slow
def test_every_route_respects_organisations_and_roles(api, superuser_email):
    spec = api.get("/api/openapi.json").json()
    victim = Victim(Tenant(api, superuser_email, "victim"))
    attackers = [
        Tenant(api, superuser_email, "attacker-b"),
        Tenant(api, superuser_email, "attacker-c"),
    ]
    # a fresh tenant for in-organisation role checks (its resources may be changed by the walk)
    home = Tenant(api, superuser_email, "home")
    home_victim = Victim(home)
    walked = 0
    for method, path, op in _operations(spec):
        if (method, path) in PUBLIC or (method, path) in SELF:
            continue
        walked += 1
        # 1. cross-organisation: attackers of every role get nothing of the victim's
        for attacker in attackers:
            for role in ("admin", "operator", "viewer"):
                url = victim.fill(path)
                r = api.request(method, url, json=_body(op, spec), headers=attacker.h(role))
                assert r.status_code < 500, (method, url, role, r.text)
                if "{" in path:
                    assert r.status_code in (403, 404, 405, 422), (
                        f"{role} of another organisation got {r.status_code} on {method} {url}: {r.text}"
                    )
                    if r.status_code == 403:
                        # role refusal must not depend on the resource: same answer for a random id
                        r2 = api.request(
                            method,
                            re.sub(r"\{(\w+)\}", str(uuid.uuid4()), path),
                            json=_body(op, spec),
                            headers=attacker.h(role),
                        )
                        assert r2.status_code == 403, (method, path, role)
                # the requested id may be echoed in a 404 message; anything else of the victim's is a leak
                leaked = [v for v in victim.secret_values if v in r.text and v not in url]
                assert not leaked, (
                    f"{method} {url} as {role} of another organisation leaked {leaked}"
                )
        # 2. in-organisation roles
        url = home_victim.fill(path)
        if method != "GET":
            r = api.request(method, url, json=_body(op, spec), headers=home.h("viewer"))
            if _matches(VIEWER_WRITES, method, path):
                assert r.status_code != 403 and r.status_code < 500, (method, path, r.text)
            else:
                assert r.status_code == 403, (
                    f"viewer could call {method} {path}: {r.status_code} {r.text}"
                )
        if _matches(ADMIN_ONLY, method, path) or _matches(SUPERUSER_ONLY, method, path):
            r = api.request(method, url, json=_body(op, spec), headers=home.h("operator"))
            assert r.status_code == 403, (
                f"operator could call {method} {path}: {r.status_code} {r.text}"
            )
        if _matches(SUPERUSER_ONLY, method, path):
            r = api.request(method, url, json=_body(op, spec), headers=home.h("admin"))
            assert r.status_code == 403, f"admin could call {method} {path}: {r.status_code}"
    assert walked >= 10


def test_unauthenticated_calls_are_401(api):
    spec = api.get("/api/openapi.json").json()
    for method, path, _ in _operations(spec):
        if (method, path) in PUBLIC:
            continue
        url = re.sub(r"\{(\w+)\}", str(uuid.uuid4()), path)
        r = api.request(method, url)
        assert r.status_code in (401, 422), (method, path, r.status_code)
        if r.status_code == 401:
            assert r.json()["error"]["code"] == "unauthorized"
