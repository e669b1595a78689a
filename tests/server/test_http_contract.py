"""What a browser front-end meets first (issue 14, items 14 and 17): CORS, trailing slashes, the
superuser's view of organisations. Real HTTP against live servers."""

from __future__ import annotations

from collections.abc import Iterator

import httpx
import pytest

from server.config import Settings
from tests.conftest import SUPERUSER_PASSWORD, LiveServer, Tenant, auth, login, test_settings

ORIGIN = "https://ops.example.com"


@pytest.fixture(scope="module")
def cors_server(database_url: str) -> Iterator[LiveServer]:
    """A server that allows one browser origin (AEROBASE_CORS_ORIGINS)."""
    server = LiveServer(test_settings(database_url, cors_origins=[ORIGIN, "http://localhost:5173"]))
    server.start()
    yield server
    server.stop()


def test_a_preflight_from_an_allowed_origin_is_answered(cors_server: LiveServer):
    """Before: no CORS at all, OPTIONS answered 405 and a browser front-end on another origin failed."""
    r = httpx.options(
        f"{cors_server.url}/api/v1/missions",
        headers={
            "Origin": ORIGIN,
            "Access-Control-Request-Method": "POST",
            "Access-Control-Request-Headers": "authorization, content-type",
        },
    )
    assert r.status_code == 200, r.text
    assert r.headers["access-control-allow-origin"] == ORIGIN
    assert "POST" in r.headers["access-control-allow-methods"]
    allowed = r.headers["access-control-allow-headers"].lower()
    assert "authorization" in allowed and "content-type" in allowed
    assert int(r.headers["access-control-max-age"]) > 0


def test_answers_to_an_allowed_origin_carry_cors_headers_errors_included(
    cors_server: LiveServer,
):
    """The browser must be able to read a 401's error envelope, and the headers it needs."""
    r = httpx.get(f"{cors_server.url}/api/v1/missions", headers={"Origin": ORIGIN})
    assert r.status_code == 401
    assert r.headers["access-control-allow-origin"] == ORIGIN
    exposed = r.headers["access-control-expose-headers"].lower()
    assert {"retry-after", "content-disposition", "x-request-id"} <= {
        h.strip() for h in exposed.split(",")
    }
    assert r.json()["error"]["code"] == "unauthorized"


def test_another_origin_is_not_allowed(cors_server: LiveServer):
    """A preflight from an origin not in the list is refused and gets no allow header."""
    r = httpx.options(
        f"{cors_server.url}/api/v1/missions",
        headers={"Origin": "https://evil.example", "Access-Control-Request-Method": "DELETE"},
    )
    assert r.status_code == 400
    assert "access-control-allow-origin" not in r.headers
    r = httpx.get(f"{cors_server.url}/api/health", headers={"Origin": "https://evil.example"})
    assert "access-control-allow-origin" not in r.headers


def test_allowed_origins_come_from_the_environment(monkeypatch: pytest.MonkeyPatch):
    """AEROBASE_CORS_ORIGINS is a comma-separated list; a trailing slash is dropped."""
    monkeypatch.setenv("AEROBASE_CORS_ORIGINS", "https://ops.example.com/, http://localhost:5173")
    assert Settings().cors_origins == ["https://ops.example.com", "http://localhost:5173"]
    monkeypatch.delenv("AEROBASE_CORS_ORIGINS")
    assert Settings().cors_origins == []


@pytest.mark.parametrize("path", ["/api/v1/missions/", "/api/v1/organizations/", "/api/health/"])
def test_a_trailing_slash_is_404_never_a_redirect(api: httpx.Client, tenant: Tenant, path: str):
    """Before: 307 to an absolute http:// URL (wrong behind TLS, and it drops a POST's intent)."""
    for method in ("GET", "POST"):
        r = api.request(method, path, headers=tenant.h("operator"), json={})
        assert r.status_code == 404, (method, r.status_code, r.headers.get("location"))
        assert "location" not in r.headers
        assert r.json()["error"]["code"] == "not_found"
        assert "no trailing slash" in r.json()["error"]["message"]
    assert api.get(path.rstrip("/"), headers=tenant.h("operator")).status_code == 200


def test_a_superuser_without_an_organisation_sees_every_organisation(
    api: httpx.Client, superuser_email: str
):
    """Before: 403 'this needs the viewer role; you have no role' on GET /organizations."""
    one, two = Tenant(api, superuser_email, "one"), Tenant(api, superuser_email, "two")
    token = login(api, superuser_email, SUPERUSER_PASSWORD, force=True)  # no organization_id
    try:
        r = api.get("/api/v1/organizations", headers=auth(token), params={"limit": 1000})
        assert r.status_code == 200, r.text
        ids = {o["id"] for o in r.json()}
        assert {one.id, two.id} <= ids
        r = api.get(f"/api/v1/organizations/{two.id}", headers=auth(token))
        assert r.status_code == 200 and r.json()["name"] == two.name
        # still no organisation's data: those routes need a role in one
        assert api.get("/api/v1/missions", headers=auth(token)).status_code == 403
    finally:
        api.post("/api/v1/auth/logout", headers=auth(token))
    # an ordinary member still sees only their own
    mine = api.get("/api/v1/organizations", headers=one.h("viewer")).json()
    assert [o["id"] for o in mine] == [one.id]


def test_an_unknown_query_parameter_is_refused_naming_it(api, tenant):
    r = api.get("/api/v1/runs", params={"limt": 10}, headers=tenant.h("viewer"))
    assert r.status_code == 422, r.text
    error = r.json()["error"]
    assert error["code"] == "validation_error" and "limt" in error["message"]
    assert error["details"] == [
        {
            "loc": ["query", "limt"],
            "msg": "not a parameter of this route",
            "type": "extra_forbidden",
        }
    ]
    # the declared ones still work, and a route's dependencies' parameters count as declared
    assert (
        api.get("/api/v1/runs", params={"limit": 10}, headers=tenant.h("viewer")).status_code == 200
    )
