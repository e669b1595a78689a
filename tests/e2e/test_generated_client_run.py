"""A whole autonomous run driven by a client generated from the OpenAPI document alone
(openapi-python-client): log in, import QGroundControl's square plan, start the run against the simulated
world and its daemons, follow its state to the end, read its timeline and its report."""

from __future__ import annotations

import json
import uuid

import pytest

from tests.conftest import Tenant
from tests.e2e.harness import platform
from tests.e2e.test_autonomous_run import WHOLE_SEQUENCE
from tests.openapi_client import generate, part
from tests.polling import eventually
from tests.server.test_missions_formats import SIMPLE_SQUARE_PLAN

pytestmark = pytest.mark.slow  # a whole flight: not in the fast lane


async def test_a_generated_client_flies_a_run_from_login_to_report(
    live_server, tenant: Tenant, tmp_path
):
    c = generate(live_server.url)
    models = part(c, "models")
    plan = json.loads(SIMPLE_SQUARE_PLAN)
    home = tuple(plan["mission"]["plannedHomePosition"])
    async with platform(live_server.url, tenant, tmp_path, pad=home) as p:
        anonymous = c.Client(base_url=live_server.url, raise_on_unexpected_status=True)
        admin = c.AuthenticatedClient(
            base_url=live_server.url, token=tenant.tokens["admin"], raise_on_unexpected_status=True
        )
        email = f"pilot-{uuid.uuid4().hex[:8]}@{tenant.name}.test"
        await part(c, "api.organizations.create_user").asyncio(
            client=admin,
            body=models.UserCreate(
                email=email, password=Tenant.PASSWORD, role=models.Role.OPERATOR
            ),
        )
        token = await part(c, "api.auth.login").asyncio(
            client=anonymous, body=models.LoginRequest(email=email, password=Tenant.PASSWORD)
        )
        pilot = c.AuthenticatedClient(
            base_url=live_server.url, token=token.access_token, raise_on_unexpected_status=True
        )

        mission = await part(c, "api.missions.import_mission").asyncio(
            client=pilot,
            body=models.ImportMissionJsonBody.from_dict(plan),
            name="generated client plan",
        )
        assert isinstance(mission, models.MissionOut) and mission.source == "qgc"

        run = await part(c, "api.runs.create_run").asyncio(
            client=pilot,
            body=models.RunCreate(
                mission_id=mission.id,
                uav_id=uuid.UUID(p.ids["uav_id"]),
                base_id=uuid.UUID(p.ids["base_id"]),
            ),
        )
        get_run = part(c, "api.runs.get_run")
        final = {models.RunState.COMPLETED, models.RunState.ABORTED, models.RunState.FAILED}

        async def finished() -> object:
            read = await get_run.asyncio(client=pilot, run_id=run.id)
            return read if read.state in final else None

        run = await eventually(finished, 150, "the run to finish", interval=0.2)
        assert run.state is models.RunState.COMPLETED, (run.reason, run.timeline)
        assert run.outcome is models.RunOutcome.COMPLETED
        assert [t.to_state.value for t in run.timeline] == [*WHOLE_SEQUENCE, "completed"]
        report = await part(c, "api.runs.get_run_report").asyncio(client=pilot, run_id=run.id)
        assert isinstance(report, models.RunReport)
        assert report.flight_time_s and report.flight_time_s > 0 and len(report.track) > 10
        assert report.landing is not None and report.landing.base_confirmed
