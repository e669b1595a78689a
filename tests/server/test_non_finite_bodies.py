"""Every operation that takes a JSON body, sent NaN, Infinity and 1e400 in every number it has,
over real HTTP: never a 5xx, and every answer strict JSON (issue 14, item 8: "anywhere").

Python's JSON reader accepts the bare tokens and reads 1e400 as Infinity, so each must be refused
by validation (or stored nowhere) and echoed, if at all, as a string.
"""

from __future__ import annotations

import json
import math
import uuid
from typing import Any

import httpx
import pytest

from tests.conftest import SUPERUSER_PASSWORD, Tenant, auth, login
from tests.server.test_authorization import Victim, _operations

pytestmark = pytest.mark.slow  # a tenant with a run and a schedule, then ~90 requests

BAD = {"NaN": float("nan"), "Infinity": float("inf"), "1e400": float("inf")}


def _full(
    schema: dict[str, Any], spec: dict[str, Any], bad: float, ids: dict[str, Any], depth: int = 0
) -> Any:
    """An instance of `schema` with every property present, arrays of one and every number `bad`;
    a property named in `ids` takes that value (real ids, so validation gets past them)."""
    if depth > 8:
        return None
    if "$ref" in schema:
        name = schema["$ref"].rsplit("/", 1)[-1]
        return _full(spec["components"]["schemas"][name], spec, bad, ids, depth + 1)
    for key in ("anyOf", "oneOf", "allOf"):
        if key in schema:
            options = [s for s in schema[key] if s.get("type") != "null"]
            return _full(options[0], spec, bad, ids, depth + 1) if options else None
    if "enum" in schema:
        return schema["enum"][0]
    kind = schema.get("type")
    if kind in ("number", "integer"):
        return bad
    if kind == "boolean":
        return False
    if kind == "array":
        items = schema.get("items") or schema.get("prefixItems", [{}])[0]
        return [_full(items, spec, bad, ids, depth + 1)] if items else [bad]
    if kind == "object" or "properties" in schema:
        props = schema.get("properties", {})
        out = {
            k: ids[k] if k in ids else _full(v, spec, bad, ids, depth + 1) for k, v in props.items()
        }
        return out or {"x": bad, "nested": {"y": [bad]}}
    if schema.get("format") == "uuid":
        return "00000000-0000-0000-0000-000000000000"
    if schema.get("format") == "date-time":
        return "2026-01-01T00:00:00Z"
    if "mail" in str(schema.get("title", "")).lower():
        return f"nan-{uuid.uuid4().hex[:8]}@nan.test"
    return f"nan-walk-{uuid.uuid4().hex[:10]}"


def _strict(text: str) -> Any:
    def refuse(token: str) -> None:
        raise AssertionError(f"{token} in an answer: not JSON")

    return json.loads(text, parse_constant=refuse) if text else None


def test_no_operation_fails_on_non_finite_numbers(api: httpx.Client, superuser_email: str):
    spec = api.get("/api/openapi.json").json()
    victim = Victim(Tenant(api, superuser_email, "nan"))
    root = login(api, superuser_email, SUPERUSER_PASSWORD, force=True)
    base = victim.tenant.create_asset("landing_base")["id"]
    ids = {
        "base_id": None,  # a new asset needs no base; a run or schedule gets the real one below
        "uav_id": victim.ids["asset_id"],
        "mission_id": victim.ids["mission_id"],
        "kind": "uav",
    }
    sent = 0
    try:
        for method, path, op in _operations(spec):
            content = op.get("requestBody", {}).get("content", {})
            if "application/json" not in content:
                continue
            headers = auth(root) if path == "/api/v1/organizations" else victim.tenant.h("admin")
            for token, bad in BAD.items():
                real = {**ids, "base_id": base} if "runs" in path or "schedules" in path else ids
                body = _full(content["application/json"]["schema"], spec, bad, real)
                text = json.dumps(body)
                # a number in the body (not the token in a random id: "...a01e4009a")
                carries = "NaN" in text or "Infinity" in text
                if token == "1e400":
                    text = text.replace("Infinity", "1e400")
                assert token in text or not math.isfinite(bad), (path, text)
                r = api.request(
                    method,
                    victim.fill(path),
                    content=text,
                    headers={**headers, "Content-Type": "application/json"},
                )
                sent += 1
                assert r.status_code < 500, (method, path, token, r.status_code, r.text[:300])
                if r.headers.get("content-type", "").startswith("application/json"):
                    _strict(r.text)
                if carries:
                    assert r.status_code >= 400, (method, path, token, r.text[:300])
    finally:
        api.post("/api/v1/auth/logout", headers=auth(root))
    assert sent >= 30
