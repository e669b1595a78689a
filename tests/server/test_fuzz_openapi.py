"""Property-based run of the whole OpenAPI document (schemathesis): no input gives a 5xx."""

from __future__ import annotations

import os

import pytest
import schemathesis
from hypothesis import HealthCheck, given, settings

from tests.conftest import Tenant

EXAMPLES = int(os.environ.get("AEROBASE_FUZZ_EXAMPLES", "25"))
# live video's WHEP/WHIP bodies are SDP text (and trickle fragments): send them as text
schemathesis.serializer.alias(["application/sdp", "application/trickle-ice-sdpfrag"], "text/plain")


@pytest.mark.slow
def test_no_route_answers_5xx(api, live_server, superuser_email):
    tenant = Tenant(api, superuser_email, "fuzz")
    schema = schemathesis.openapi.from_url(f"{live_server.url}/api/openapi.json")
    failures: list[str] = []
    operations = [r.ok() for r in schema.get_all_operations()]
    assert len(operations) >= 10

    def check(operation, headers) -> None:  # type: ignore[no-untyped-def]
        @settings(
            max_examples=EXAMPLES,
            deadline=None,
            database=None,
            suppress_health_check=list(HealthCheck),
        )
        @given(case=operation.as_strategy())
        def run(case) -> None:  # type: ignore[no-untyped-def]
            response = case.call(base_url=live_server.url, headers=headers)
            if response.status_code >= 500:
                failures.append(
                    f"{case.method} {case.formatted_path} -> {response.status_code}: "
                    f"{response.text[:200]}"
                )

        run()

    for operation in operations:
        if operation.path in ("/api/v1/auth/logout", "/api/v1/auth/renew"):
            continue  # would end the very sessions the run uses; covered by test_auth
        for role in ("admin", "viewer", None):
            check(operation, tenant.h(role) if role else {})
    assert not failures, "\n".join(failures[:20])
