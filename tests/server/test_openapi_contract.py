"""The served OpenAPI document is a contract a generated client can use (issue 14 item 16): each
operation's error statuses declared with the envelope, one bearer scheme, short unique operationIds
(each in frontend_api.md), named enumerations, every field described. The derivation of error
statuses from a route's dependencies is tested on an app of its own."""

from __future__ import annotations

import re
import typing
from pathlib import Path
from typing import Annotated, Any

from fastapi import Depends, FastAPI
from fastapi.testclient import TestClient
from pydantic import BaseModel

from protocol.vocabulary import CommandStatus as WireCommandStatus
from server.commands.schemas import CommandStatus
from server.kit.errors import AppError, Conflict
from server.kit.openapi import declares, errors, install

ROOT = Path(__file__).resolve().parents[2]
ENVELOPE = {"$ref": "#/components/schemas/ErrorEnvelope"}
PUBLIC = {"login", "assetLogin", "getHealth", "getReadiness"}


def _operations(spec: dict[str, Any]) -> list[tuple[str, str, dict[str, Any]]]:
    return [(m.upper(), p, op) for p, item in spec["paths"].items() for m, op in item.items()]


def test_every_error_status_is_declared_with_the_envelope(api):
    spec = api.get("/api/openapi.json").json()
    for method, path, op in _operations(spec):
        statuses = set(op["responses"])
        assert "422" in statuses, (method, path)  # an unknown query parameter, everywhere
        if op["operationId"] not in PUBLIC:
            assert {"401", "422"} <= statuses, (method, path, statuses)
        if "{" in path:
            assert "404" in statuses, (method, path)
        if "requestBody" in op:
            assert {"400", "413"} <= statuses, (method, path)
        for status, response in op["responses"].items():
            if int(status) >= 400 and op["operationId"] not in ("getHealth", "getReadiness"):
                schema = response["content"]["application/json"]["schema"]
                assert schema == ENVELOPE, (method, path, status, schema)
    assert "HTTPValidationError" not in spec["components"]["schemas"]  # FastAPI's shape, not ours
    info = spec["components"]["schemas"]["ErrorInfo"]
    assert set(info["required"]) == {"code", "message"} and "details" in info["properties"]


def test_statuses_that_depend_on_the_route_are_declared_where_they_occur(api):
    spec = api.get("/api/openapi.json").json()
    by_id = {op["operationId"]: op for _, _, op in _operations(spec)}
    assert "429" in by_id["login"]["responses"] and "429" in by_id["assetLogin"]["responses"]
    assert "401" in by_id["login"]["responses"]  # wrong credentials
    assert "403" in by_id["listMissions"]["responses"] and "403" not in by_id["getMe"]["responses"]
    assert "403" in by_id["listOrganizations"]["responses"]
    assert "409" in by_id["createRun"]["responses"] and "409" in by_id["deleteMission"]["responses"]
    assert "415" in by_id["importMission"]["responses"]
    assert "503" in by_id["getReadiness"]["responses"]
    assert "404" not in by_id["listMissions"]["responses"]


def test_one_bearer_scheme_required_by_every_operation_but_the_public_ones(api):
    spec = api.get("/api/openapi.json").json()
    schemes = spec["components"]["securitySchemes"]
    assert schemes == {"bearerAuth": schemes["bearerAuth"]}
    assert schemes["bearerAuth"]["type"] == "http" and schemes["bearerAuth"]["scheme"] == "bearer"
    for method, path, op in _operations(spec):
        if op["operationId"] in PUBLIC:
            assert "security" not in op, (method, path)
        else:
            assert op.get("security") == [{"bearerAuth": []}], (method, path)


def test_operation_ids_are_short_unique_and_documented(api):
    spec = api.get("/api/openapi.json").json()
    doc = (ROOT / "frontend_api.md").read_text()
    ids = [op["operationId"] for _, _, op in _operations(spec)]
    assert len(ids) == len(set(ids)), sorted(i for i in ids if ids.count(i) > 1)
    for method, path, op in _operations(spec):
        oid = op["operationId"]
        assert re.fullmatch(r"[a-z][A-Za-z]{2,29}", oid), (method, path, oid)
        # the heading of the endpoint names its id: renaming one is a documented change
        assert f"### {method} {path} · `{oid}`" in doc, (method, path, oid)
    assert {"listMissions", "createRun", "getRun", "abortRun", "login"} <= set(ids)


def test_states_statuses_and_roles_are_named_enumerations(api):
    spec = api.get("/api/openapi.json").json()
    schemas = spec["components"]["schemas"]
    enums = {
        "RunState": {
            "pending",
            "checking",
            "flying",
            "charging",
            "completed",
            "incomplete",
            "aborted",
            "failed",
        },
        "RunOutcome": {"completed", "completed_with_issues", "incomplete", "aborted", "failed"},
        "RunIssue": {"charging_refused", "landing_off_contacts"},
        "CommandStatus": {"queued", "succeeded", "timed_out"},
        "Role": {"viewer", "operator", "admin"},
        "AssetKind": {"uav", "landing_base"},
        "MissionKind": {"waypoints", "survey"},
        "ScheduleKind": {"once", "interval", "cron"},
        "MissedPolicy": {"skip", "run_once"},
        "PrincipalKind": {"user", "asset"},
        "ActorKind": {"user", "asset"},
    }
    for name, some in enums.items():
        assert some <= set(schemas[name]["enum"]), name

    def ref(schema: str, field: str) -> str:
        return str(schemas[schema]["properties"][field])

    assert "RunState" in ref("RunOut", "state") and "RunState" in ref("TransitionOut", "to_state")
    assert "RunOutcome" in ref("RunOut", "outcome")
    assert "RunIssue" in ref("RunOut", "issues")
    assert "RunOutcome" in str(schemas["FleetReport"]["properties"]["by_outcome"])
    assert "CommandStatus" in ref("CommandOut", "status")
    assert "Role" in ref("MembershipOut", "role") and "Role" in ref("MeResponse", "role")
    assert "ScheduleKind" in ref("ScheduleOut", "kind")


def test_the_command_status_enumeration_is_the_wire_vocabulary():
    assert {s.value for s in CommandStatus} == set(typing.get_args(WireCommandStatus))


def test_every_field_is_described_and_examples_are_valid_shapes(api):
    spec = api.get("/api/openapi.json").json()
    undescribed = [
        f"{name}.{field}"
        for name, schema in spec["components"]["schemas"].items()
        for field, prop in schema.get("properties", {}).items()
        if not prop.get("description")
    ]
    assert not undescribed, undescribed
    examples = [
        prop["examples"]
        for schema in spec["components"]["schemas"].values()
        for prop in schema.get("properties", {}).values()
        if "examples" in prop
    ]
    assert len(examples) > 100 and all(isinstance(e, list) and e for e in examples)


# -- the derivation itself, on an app of its own ----------------------------------------------


class PreconditionFailed(AppError):
    """The resource changed since the caller read it (If-Match)."""

    status, code = 412, "precondition_failed"


class LostRace(Conflict):
    """Another write won the race."""

    code = "edit_conflict"


@declares(PreconditionFailed, LostRace)
def if_match() -> None:
    """A shared check: every route using it answers 412 (or 409) when it fails."""


class Thing(BaseModel):
    name: str


def _toy() -> FastAPI:
    app = FastAPI()

    @app.put("/things/{thing_id}", responses=errors(Conflict))
    def put_thing(thing_id: int, body: Thing, _: Annotated[None, Depends(if_match)]) -> Thing:
        return body

    @app.get("/things")
    def list_things() -> list[Thing]:
        return []

    install(app, {"name": ("the thing's name", "spoon")}, {})
    return app


def test_a_dependency_declares_its_error_on_every_route_that_uses_it():
    spec = TestClient(_toy()).get("/openapi.json").json()
    put = spec["paths"]["/things/{thing_id}"]["put"]["responses"]
    assert {"400", "404", "409", "412", "413", "422"} <= set(put)
    assert "precondition_failed" in put["412"]["description"]
    assert put["412"]["content"]["application/json"]["schema"] == ENVELOPE
    # the route's own 409 and the dependency's are one response naming both codes
    assert "`conflict`" in put["409"]["description"]
    assert "`edit_conflict`" in put["409"]["description"]
    listing = spec["paths"]["/things"]["get"]["responses"]
    assert set(listing) == {"200", "422"}
    name = spec["components"]["schemas"]["Thing"]["properties"]["name"]
    assert name["description"] == "the thing's name" and name["examples"] == ["spoon"]


EDITED = (
    "/api/v1/missions/{mission_id}",
    "/api/v1/schedules/{schedule_id}",
    "/api/v1/users/{user_id}",
    "/api/v1/assets/{asset_id}",
)


def test_edits_declare_what_if_match_answers_and_answers_declare_their_etag(api):
    """The If-Match dependency declares 400 (not a list of tags), 412 (another version) and 409
    (a lost race) on every PATCH and DELETE reading it; GET/PATCH 200 and POST 201 carry ETag."""
    spec = api.get("/api/openapi.json").json()
    for path in EDITED:
        ops = spec["paths"][path]
        for method in ("patch", "delete"):
            responses = ops[method]["responses"]
            for status, code in (("400", "bad_request"), ("409", "edit_conflict")):
                assert f"`{code}`" in responses[status]["description"], (path, method, status)
            assert "`precondition_failed`" in responses["412"]["description"], (path, method)
            for status in ("400", "409", "412"):
                schema = responses[status]["content"]["application/json"]["schema"]
                assert schema == ENVELOPE, (path, method, status)
        for method in ("get", "patch"):
            assert "ETag" in ops[method]["responses"]["200"]["headers"], (path, method)
        assert "412" not in ops["get"]["responses"], path
    for path in (
        "/api/v1/missions",
        "/api/v1/missions/import",
        "/api/v1/schedules",
        "/api/v1/users",
        "/api/v1/assets",
    ):
        assert "ETag" in spec["paths"][path]["post"]["responses"]["201"]["headers"], path
