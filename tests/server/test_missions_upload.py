"""Missions reach the autopilot as they are: our items uploaded to the simulated autopilot over MAVLink UDP."""

# ruff: noqa: F811  (the agent tests' fixtures are imported by name and requested as parameters)

from __future__ import annotations

import json

from asset_agent.autopilot import Autopilot, items_from_dicts
from server.missions.items import item_dicts
from server.missions.qgc import parse_plan
from server.missions.survey import SurveySpec, compile_survey
from sim.vehicle.server import VehicleServer
from tests.asset_agent.conftest import autopilot, pad, vehicle  # noqa: F401  (fixtures)
from tests.server.test_missions_formats import SIMPLE_SQUARE_PLAN

PAD = (41.1780, -8.5960)
D = 0.0015
AREA = ((PAD[1], PAD[0]), (PAD[1] + D, PAD[0]), (PAD[1] + D, PAD[0] + D), (PAD[1], PAD[0] + D))


async def _round_trip(ap: Autopilot, dicts: list[dict]) -> None:
    items = items_from_dicts(dicts)
    await ap.upload_mission(items)  # the adapter reads it back and compares
    back = await ap.download_mission()
    assert len(back) == len(items)
    assert all(a.same_as(b) is None for a, b in zip(items, back, strict=True))


async def test_an_imported_qgroundcontrol_plan_uploads(
    autopilot: Autopilot, vehicle: VehicleServer
):
    dicts = item_dicts(parse_plan(json.loads(SIMPLE_SQUARE_PLAN)).items)
    await _round_trip(autopilot, dicts)
    assert len(vehicle.copter.items) == 1 + len(dicts)


async def test_a_compiled_survey_uploads(autopilot: Autopilot, vehicle: VehicleServer):
    spec = SurveySpec(AREA, 40, 30, 70, 60, 30, 5.0, takeoff=PAD, camera_trigger=False)
    dicts = item_dicts(list(compile_survey(spec).items))
    assert len(dicts) > 10
    await _round_trip(autopilot, dicts)
