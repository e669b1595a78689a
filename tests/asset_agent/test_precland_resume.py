"""What an agent restarted while it flew the landing itself does with the vehicle it first finds
(resume.py); against the simulated autopilot in test_precland_takeover.py."""

from __future__ import annotations

from dataclasses import replace
from typing import Any

import pytest

from asset_agent.autopilot.state import UavState
from asset_agent.precland.resume import FLYING, HOLDING, TakeoverRecord, decide


def found(**changes: Any) -> UavState:
    """What a restarted agent first finds: armed in the air in GUIDED, its state known."""
    base = UavState(link_up=True, custom_mode=4, armed=True, mode="GUIDED", landed_state="IN_AIR")
    return replace(base, **changes)


@pytest.mark.parametrize(
    ("left", "changes", "decision"),
    [
        (FLYING, {}, "resume"),
        (HOLDING, {}, "hold"),
        (None, {}, "none"),  # a pilot's GUIDED
        (FLYING, {"mode": "LAND"}, "none"),  # handed back already
        (
            FLYING,
            {"armed": False, "landed_state": "ON_GROUND"},
            "none",
        ),  # landed (by hand, or a failsafe)
    ],
)
def test_a_restarted_agent_resumes_only_the_landing_its_predecessor_flew(
    left: str | None, changes: dict[str, object], decision: str
) -> None:
    assert decide(left, found(**changes)) == decision


def test_the_decision_waits_for_the_vehicles_state_and_is_taken_once() -> None:
    record = TakeoverRecord(left=FLYING)
    assert record.first_sight(found(custom_mode=None)) is None  # no HEARTBEAT yet
    assert record.first_sight(found(landed_state="UNDEFINED")) is None
    assert record.first_sight(found()) == "resume"
    assert record.first_sight(found()) is None
