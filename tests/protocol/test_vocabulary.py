"""The command vocabulary: every command parses from its wire pair, bad params name the field."""

from __future__ import annotations

import typing
from pathlib import Path

import pytest
from pydantic import ValidationError

from protocol import vocabulary as v
from protocol.codec import decode
from protocol.messages import Command, CommandResultPayload

EXAMPLES: dict[str, dict[str, object]] = {
    "check_availability": {"mass_g": 1450.0, "mass_window_g": 300.0},
    "upload_mission": {
        "mission_id": "5a0c7e1b-3f9d-4e2a-b6c8-1d4f7a9e2c30",
        "items": [
            {"command": 22, "frame": 3, "params": [0, 0, 0, None], "lat": 41.1, "alt": 20},
            {"command": 20, "frame": 2},
        ],
    },
    "start_charging": {"current_limit_ma": 4000},
    "precland_fault": {"source": "ir", "r_drop": 0.3, "below_m": 2.0},
}


@pytest.mark.parametrize("name", sorted(v.COMMANDS))
def test_every_command_parses_and_round_trips(name: str) -> None:
    command = v.parse(name, EXAMPLES.get(name, {}))
    assert command.name == name and isinstance(command, v.COMMANDS[name])
    assert v.parse(name, v.params_of(command)) == command


def test_the_union_and_the_registry_name_the_same_commands() -> None:
    assert set(typing.get_args(v.AssetCommand)) == set(v.COMMANDS.values())


def test_unknown_name_and_unknown_field_are_refused() -> None:
    with pytest.raises(v.UnknownCommand, match="teleport"):
        v.parse("teleport", {})
    with pytest.raises(ValidationError) as err:
        v.parse("open", {"fast": True})
    assert v.describe(err.value).startswith("fast:")


@pytest.mark.parametrize(
    ("params", "where"),
    [
        ({"items": []}, "items"),
        ({"items": [{"command": 16, "lat": 123.0}]}, "items.0.lat"),
        ({"items": [{"command": 16, "frame": 4}]}, "items.0.frame"),
        ({"items": [{"command": 0}]}, "items.0.command"),
        ({"items": [{"command": 16, "params": [0, 0, 0]}]}, "items.0.params"),
    ],
)
def test_mission_items_are_checked_by_field(params: dict[str, object], where: str) -> None:
    with pytest.raises(ValidationError) as err:
        v.parse("upload_mission", params)
    assert v.describe(err.value).split(":")[0].startswith(where)


@pytest.mark.parametrize("limit", [True, "500", 5.5, -1, 70000])
def test_charge_current_limit_is_an_integer_in_range(limit: object) -> None:
    with pytest.raises(ValidationError, match="current_limit_ma"):
        v.parse("start_charging", {"current_limit_ma": limit})


def test_availability_report_lists_failures_consistently() -> None:
    ok = v.AvailabilityCondition(name="wind", ok=True, value=3.0, limit=8.0, message="wind 3")
    bad = v.AvailabilityCondition(name="rain", ok=False, value=2.5, limit=0.0, message="rain")
    report = v.AvailabilityReport.of([ok, bad])
    assert not report.available and report.failed == (bad,) and report.summary == "rain"
    assert v.AvailabilityReport.model_validate(report.model_dump(mode="json")) == report
    with pytest.raises(ValidationError):
        v.AvailabilityReport(available=True, conditions=(bad,), failed=(bad,))
    assert v.AvailabilityReport.of([ok]).available


def test_final_statuses_are_the_ones_a_result_ends_on() -> None:
    finals = {s for s in typing.get_args(v.CommandStatus) if CommandResultPayload(status=s).final}
    assert finals == v.FINAL_STATUSES


def test_the_golden_command_is_a_command_of_the_vocabulary() -> None:
    text = (Path(__file__).parent / "golden" / "command.json").read_text()
    msg = decode(text, "server_to_asset")
    assert isinstance(msg, Command)
    assert v.parse(msg.payload.name, msg.payload.params) == v.StartCharging(current_limit_ma=4000)
