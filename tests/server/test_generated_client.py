"""A client generated from the served OpenAPI document (openapi-python-client) works against the
live server: it logs in, registers a base and a UAV, creates and reads a mission, starts a run
and reads it, and every error reaches it as the typed error envelope. The whole flight through the
generated client is tests/e2e/test_generated_client_run.py."""

from __future__ import annotations

import uuid
from http import HTTPStatus

from tests.conftest import Tenant
from tests.e2e.harness import mission_items
from tests.openapi_client import generate, part


def test_a_generated_client_drives_the_api_and_reads_typed_errors(live_server, tenant: Tenant):
    c = generate(live_server.url)
    models = part(c, "models")
    anonymous = c.Client(base_url=live_server.url, raise_on_unexpected_status=True)
    login = part(c, "api.auth.login")

    # a wrong password: 401 with the envelope, parsed into its model
    wrong = login.sync_detailed(
        client=anonymous,
        body=models.LoginRequest(email=tenant.emails["operator"], password="not-the-password"),
    )
    assert wrong.status_code == HTTPStatus.UNAUTHORIZED
    assert isinstance(wrong.parsed, models.ErrorEnvelope)
    assert wrong.parsed.error.code == "invalid_credentials"

    admin = c.AuthenticatedClient(
        base_url=live_server.url, token=tenant.tokens["admin"], raise_on_unexpected_status=True
    )
    email = f"generated-{uuid.uuid4().hex[:8]}@{tenant.name}.test"
    user = part(c, "api.organizations.create_user").sync(
        client=admin,
        body=models.UserCreate(email=email, password=Tenant.PASSWORD, role=models.Role.OPERATOR),
    )
    assert isinstance(user, models.UserOut) and user.role is models.Role.OPERATOR
    token = login.sync(
        client=anonymous, body=models.LoginRequest(email=email, password=Tenant.PASSWORD)
    )
    assert isinstance(token, models.TokenResponse)
    operator = c.AuthenticatedClient(
        base_url=live_server.url, token=token.access_token, raise_on_unexpected_status=True
    )
    me = part(c, "api.auth.get_me").sync(client=operator)
    assert me.kind is models.PrincipalKind.USER and me.role is models.Role.OPERATOR

    create_asset = part(c, "api.assets.create_asset")
    base = create_asset.sync(
        client=admin,
        body=models.AssetCreate.from_dict(
            {
                "name": f"base-{uuid.uuid4().hex[:8]}",
                "kind": "landing_base",
                "password": "asset-password-123",
                "attributes": {"latitude": 47.397742, "longitude": 8.545594},
            }
        ),
    )
    uav = create_asset.sync(
        client=admin,
        body=models.AssetCreate.from_dict(
            {
                "name": f"uav-{uuid.uuid4().hex[:8]}",
                "kind": "uav",
                "password": "asset-password-123",
                "base_id": str(base.id),
                "attributes": {"mass_g": 1450},
            }
        ),
    )
    assert base.kind is models.AssetKind.LANDING_BASE and uav.kind is models.AssetKind.UAV

    mission = part(c, "api.missions.create_mission").sync(
        client=operator,
        body=models.MissionCreate.from_dict(
            {"name": "generated square", "items": mission_items(47.397742, 8.545594)}
        ),
    )
    assert isinstance(mission, models.MissionOut) and mission.kind is models.MissionKind.WAYPOINTS
    read = part(c, "api.missions.get_mission").sync(client=operator, mission_id=mission.id)
    assert read.id == mission.id and len(read.items) == 5
    listed = part(c, "api.missions.list_missions").sync(client=operator)
    assert mission.id in {m.id for m in listed}

    missing = part(c, "api.missions.get_mission").sync_detailed(
        client=operator, mission_id=uuid.uuid4()
    )
    assert missing.status_code == HTTPStatus.NOT_FOUND
    assert isinstance(missing.parsed, models.ErrorEnvelope)
    assert missing.parsed.error.code == "not_found"

    # a run is started and read back through the client (no daemons here: it waits at its check)
    ids = {"mission_id": mission.id, "uav_id": uav.id, "base_id": base.id}
    run = part(c, "api.runs.create_run").sync(client=operator, body=models.RunCreate(**ids))
    assert isinstance(run, models.RunOut) and isinstance(run.state, models.RunState)
    busy = part(c, "api.runs.create_run").sync_detailed(
        client=operator, body=models.RunCreate(**ids)
    )
    assert busy.status_code == HTTPStatus.CONFLICT and busy.parsed.error.code == "asset_busy"
    again = part(c, "api.runs.get_run").sync(client=operator, run_id=run.id)
    assert again.id == run.id and all(
        isinstance(t.to_state, models.RunState) for t in again.timeline
    )
    aborted = part(c, "api.runs.abort_run").sync(
        client=operator, run_id=run.id, body=models.AbortRequest(reason="generated client")
    )
    assert aborted.abort_requested
