"""The server starts, serves its OpenAPI document and reports database health."""


def test_health_reports_database(api):
    r = api.get("/api/health")
    assert r.status_code == 200
    assert r.json()["database"] == "ok"


def test_openapi_document_is_served(api):
    r = api.get("/api/openapi.json")
    assert r.status_code == 200
    assert "/api/v1/auth/login" in r.json()["paths"]


def test_tenant_bootstrap(tenant, api):
    r = api.get("/api/v1/auth/me", headers=tenant.h("operator"))
    assert r.status_code == 200, r.text
    assert r.json()["role"] == "operator"
    assert r.json()["organization_id"] == tenant.id


def test_nul_bytes_in_urls_are_a_client_error(api, tenant):
    r = api.get("/api/v1/audit", params={"action": "\x00x"}, headers=tenant.h("admin"))
    assert r.status_code == 422 and r.json()["error"]["code"] == "validation_error"
