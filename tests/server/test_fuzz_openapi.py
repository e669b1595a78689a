"""Property-based run of the whole OpenAPI document (schemathesis) against the live server: no input
gives a 5xx, and every answer (to data that fits the document and to data that does not) is one the document declares — its status code, its content type and
its body's schema (the error envelope included). This is what a generated client relies on."""

from __future__ import annotations

import datetime
import os
import time
import uuid
from collections import Counter

import httpx
import pytest
import schemathesis
from hypothesis import HealthCheck, given, settings
from hypothesis.errors import Unsatisfiable
from schemathesis import GenerationMode
from schemathesis.checks import (
    FailureGroup,
    content_type_conformance,
    not_a_server_error,
    response_schema_conformance,
    status_code_conformance,
)

from tests.conftest import Tenant

EXAMPLES = int(os.environ.get("AEROBASE_FUZZ_EXAMPLES", "25"))  # per operation, role and mode
# negative data mostly meets the same few refusals (a 422 naming the field): fewer cases suffice
EXAMPLES_BY_MODE = {
    GenerationMode.POSITIVE: EXAMPLES,
    GenerationMode.NEGATIVE: max(1, EXAMPLES * 2 // 5),
}
CHECKS = [
    not_a_server_error,
    status_code_conformance,
    content_type_conformance,
    response_schema_conformance,
]
# would end the very sessions the run uses; their contract is covered by test_auth
SESSION_ENDERS = ("/api/v1/auth/logout", "/api/v1/auth/renew")
# live video's WHEP/WHIP bodies are SDP text (and trickle fragments): send them as text
schemathesis.serializer.alias(["application/sdp", "application/trickle-ice-sdpfrag"], "text/plain")


def _stored(api: httpx.Client, tenant: Tenant) -> dict[str, str]:
    """Ids of things the tenant has, by path parameter: a base and its UAV that flew a run of a
    mission, a zone, a schedule. Random ids only ever meet 404; these reach the code behind it
    (a zone patched to a null geometry, an asset with runs deleted: both were 500s)."""
    base = tenant.create_asset("landing_base")
    uav = tenant.create_asset("uav", base_id=base["id"], attributes={"mass_g": 1450})
    h = tenant.h("operator")
    mission = tenant.create_mission("fuzzed")
    ids = {"mission_id": mission["id"], "uav_id": uav["id"], "base_id": base["id"]}
    run = api.post("/api/v1/runs", json=ids, headers=h)
    zone = tenant.create_zone("fuzzed")
    next_year = (datetime.datetime.now(datetime.UTC) + datetime.timedelta(days=365)).isoformat()
    schedule = api.post(
        "/api/v1/schedules",
        json={**ids, "name": "fuzzed", "kind": "once", "at": next_year},
        headers=h,
    )
    made = (run, schedule)
    assert all(r.status_code == 201 for r in made), [r.text for r in made]
    return {
        "asset_id": uav["id"],
        "mission_id": ids["mission_id"],
        "run_id": run.json()["id"],
        "zone_id": zone["id"],
        "schedule_id": schedule.json()["id"],
    }


@pytest.mark.slow
@pytest.mark.cpu_bound  # generating cases: at the lowest priority beside real-time tests
@pytest.mark.timeout(900)  # ~5,000 requests: 2-4 min on the loaded 2-core machine
def test_every_answer_is_declared_and_none_is_a_server_error(api, live_server, superuser_email):
    tenant = Tenant(api, superuser_email, "fuzz")
    stored = _stored(api, tenant)
    schema = schemathesis.openapi.from_url(f"{live_server.url}/api/openapi.json")
    operations = [r.ok() for r in schema.get_all_operations()]
    assert len(operations) >= 40
    failures: list[str] = []
    statuses: Counter[int] = Counter()
    cases = 0
    negative_impossible: set[str] = set()
    started = time.monotonic()

    def fuzz(operation, headers, mode) -> None:  # type: ignore[no-untyped-def]
        @settings(
            max_examples=EXAMPLES_BY_MODE[mode],
            deadline=None,
            database=None,
            suppress_health_check=list(HealthCheck),
        )
        @given(case=operation.as_strategy(mode))
        def run(case) -> None:  # type: ignore[no-untyped-def]
            nonlocal cases
            cases += 1
            if cases % 2 and case.path_parameters:  # every other case on stored things
                for name in case.path_parameters.keys() & stored.keys():
                    case.path_parameters[name] = stored[name]
            response = case.call(base_url=live_server.url, headers=headers)
            statuses[response.status_code] += 1
            try:
                case.validate_response(response, checks=CHECKS)
            except FailureGroup as failure:  # each case's failures are recorded, all reported
                failures.append(
                    f"{case.method} {case.formatted_path} -> {response.status_code}: "
                    f"{str(failure).strip()[:400]}\n  body: {response.text[:200]}"
                )

        try:
            run()
        except Unsatisfiable:
            # no parameter and no body: nothing of the operation can be made invalid
            assert mode is GenerationMode.NEGATIVE and not operation.body, operation.label
            negative_impossible.add(operation.label)

    for operation in operations:
        if operation.path in SESSION_ENDERS:
            continue
        for role in ("admin", "viewer", None):
            # data that fits the document, and data that does not (which must meet a declared 4xx)
            for mode in (GenerationMode.POSITIVE, GenerationMode.NEGATIVE):
                fuzz(operation, tenant.h(role) if role else {}, mode)
    took = time.monotonic() - started
    # the figures the README quotes
    print(
        f"\nschema fuzz: {len(operations)} operations, {cases} cases in {took:.0f} s; "
        f"statuses {dict(sorted(statuses.items()))}"
    )
    assert not failures, f"{len(failures)} of {cases} cases:\n" + "\n".join(failures[:25])


def _answer(status: int, body: object, url: str) -> httpx.Response:
    response = httpx.Response(status, json=body, request=httpx.Request("GET", url))
    response.read()
    response.elapsed = datetime.timedelta(0)
    return response


def test_the_checks_refuse_an_undeclared_status_and_a_body_off_the_envelope(api):
    """The fuzz's checks themselves, on the served document: a status the operation does not
    declare, or an error body not in the envelope, is a failure; a declared one passes."""
    document = api.get("/api/openapi.json").json()
    path = "/api/v1/missions/{mission_id}"
    url = f"http://server/api/v1/missions/{uuid.uuid4()}"
    not_found = {"error": {"code": "not_found", "message": "no such mission", "details": None}}
    operation = schemathesis.openapi.from_dict(document)[path]["GET"]
    case = operation.Case(path_parameters={"mission_id": str(uuid.uuid4())})
    case.validate_response(_answer(404, not_found, url), checks=CHECKS)  # declared: passes
    with pytest.raises(FailureGroup, match="JSON"):
        case.validate_response(_answer(404, {"detail": "Not Found"}, url), checks=CHECKS)
    with pytest.raises(FailureGroup, match="Undocumented status code"):
        case.validate_response(_answer(418, not_found, url), checks=CHECKS)
