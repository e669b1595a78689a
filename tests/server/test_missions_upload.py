"""Missions reach the autopilot as they are: our items uploaded to the simulated autopilot over MAVLink UDP."""

# ruff: noqa: F811  (the agent tests' fixtures are imported by name and requested as parameters)

from __future__ import annotations

import json

from asset_agent.autopilot import Autopilot, items_from_dicts
from asset_agent.autopilot.verify import compare
from server.missions.items import COMMANDS, MissionItem, item_dicts
from server.missions.qgc import parse_plan
from server.missions.survey import SurveySpec, compile_survey
from server.missions.validate import MissionLimits, validate_items
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
    assert all(compare(a, b) is None for a, b in zip(items, back, strict=True))


async def test_an_imported_qgroundcontrol_plan_uploads(
    autopilot: Autopilot, vehicle: VehicleServer
):
    dicts = item_dicts(parse_plan(json.loads(SIMPLE_SQUARE_PLAN)).items)
    await _round_trip(autopilot, dicts)
    assert len(vehicle.copter.items) == 1 + len(dicts)


async def test_a_compiled_survey_uploads(autopilot: Autopilot, vehicle: VehicleServer):
    for trigger in (True, False):
        spec = SurveySpec(AREA, 40, 30, 70, 60, 30, 5.0, takeoff=PAD, camera_trigger=trigger)
        dicts = item_dicts(list(compile_survey(spec).items))
        assert (206 in [d["command"] for d in dicts]) == trigger
        await _round_trip(autopilot, dicts)


async def test_every_supported_command_uploads(autopilot: Autopilot, vehicle: VehicleServer):
    items = [MissionItem(command=22, params=(0, 0, 0, None), lat=PAD[0], lon=PAD[1], alt=20)]
    for command, spec in sorted(COMMANDS.items()):
        if command == 177:
            items.append(MissionItem(command=command, frame=2, params=(2, 1, 0, 0)))
        elif command == 178:
            items.append(MissionItem(command=command, frame=2, params=(1, 6, -1, 0)))
        elif spec.positional:
            items.append(
                MissionItem(
                    command=command,
                    frame=3,
                    params=(1, 0, 5, None),
                    lat=PAD[0] + 1e-4,
                    lon=PAD[1],
                    alt=25,
                )
            )
        else:
            items.append(MissionItem(command=command, frame=2, params=(1, 0, 0, 0)))
    assert validate_items(items, MissionLimits()) == []
    await _round_trip(autopilot, item_dicts(items))
