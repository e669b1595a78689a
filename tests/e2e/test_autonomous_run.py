"""The autonomous run end to end, and each injected fault ending in its documented, safe outcome."""

from __future__ import annotations

from tests.conftest import Tenant
from tests.e2e.harness import FINAL, platform


async def test_a_run_walks_the_whole_sequence_and_completes(live_server, tenant: Tenant, tmp_path):
    async with platform(live_server.url, tenant, tmp_path) as p:
        run_id = await p.start_run()
        body = await p.wait_state(run_id, FINAL, 150)
        assert body["state"] == "completed", (body["reason"], body["timeline"])
        assert [t["to_state"] for t in body["timeline"]] == [
            "checking", "opening", "uploading", "flying", "landing", "confirming", "closing", "charging",
            "completed"]
        assert not p.world.base.can_vehicle_leave()  # closed again
        report = (await p.api.get(f"/api/v1/runs/{run_id}/report", headers=tenant.h("viewer"))).json()
        assert report["flight_time_s"] > 0 and len(report["track"]) > 10
