"""What an ended run achieved (server/runs/outcome.py) over the machine's real exits, and the
fleet report's counts of it: the issue's eight runs, of which four did the job cleanly."""

from __future__ import annotations

import uuid
from datetime import UTC, datetime, timedelta

import pytest

from server.runs.machine import FINAL, CommandOutcome, Observations, State, Transition, advance
from server.runs.models import Run
from server.runs.outcome import Flight, RunIssue, RunOutcome, judge
from server.runs.service import fleet

OK = CommandOutcome("succeeded")
OFF = CommandOutcome("rejected", "start_charging refused: UAV contacts not seated on the pad")
FAULT = CommandOutcome("rejected", "start_charging refused: charger fault")
FLOWN = Flight(mission_finished=True)
CHARGE = ("base", "start_charging")


def obs(**kw):  # type: ignore[no-untyped-def]
    return Observations(**{"elapsed_s": 1.0, "timeout_s": 60.0, "commands": {}, **kw})


def ended(charging: CommandOutcome, *, aborting: bool = False) -> Transition:
    t = advance(State.charging, obs(commands={CHARGE: charging}), aborting=aborting)
    assert t is not None and t.to in FINAL
    return t


@pytest.mark.parametrize(
    ("charging", "flight", "outcome", "cause", "issues", "alert"),
    [
        (OK, FLOWN, "completed", None, (), False),
        (FAULT, FLOWN, "completed_with_issues", "charging_refused", ("charging_refused",), True),
        (OFF, FLOWN, "completed_with_issues", "landing_off_contacts", ("landing_off_contacts",), True),
        (OK, Flight(returned="battery_reserve"), "incomplete", "battery_reserve", (), True),
        (OK, Flight(returned="fence_breach"), "incomplete", "fence_breach", (), True),
        (OK, Flight(returned="returned_early", operator_return=True), "incomplete", "operator_return", (), False),
        (OK, Flight(returned="returned_early"), "incomplete", "returned_early", (), True),
        (FAULT, Flight(returned="battery_reserve"), "incomplete", "battery_reserve", ("charging_refused",), True),
        (OK, Flight(mission_finished=True, landed_without_precision=True), "completed_with_issues", "landed_without_precision", ("landed_without_precision",), True),
        (FAULT, Flight(mission_finished=True, landed_without_precision=True), "completed_with_issues", "charging_refused", ("charging_refused", "landed_without_precision"), True),
    ],
)  # fmt: skip
def test_a_run_that_reached_charging_is_completed_only_with_its_mission_flown(
    charging, flight, outcome, cause, issues, alert
):  # type: ignore[no-untyped-def]
    verdict = judge(ended(charging), flight, charging)
    assert verdict.outcome == outcome
    assert verdict.cause == cause
    assert tuple(i.value for i in verdict.issues) == issues
    assert verdict.transition.alert is alert
    final = State.completed if outcome.startswith("completed") else State.incomplete
    assert verdict.transition.to == final
    if outcome == "incomplete":
        assert "not flown to its last item" in verdict.transition.reason


ABORT = {"abort_requested": True, "abort_reason": "fog"}


@pytest.mark.parametrize(
    "phase",
    [
        State.pending, State.checking, State.opening, State.uploading, State.flying,
        State.landing, State.confirming, State.closing, State.charging,
    ],
)  # fmt: skip
def test_an_abort_in_each_phase_ends_aborted_by_the_operator_without_an_alert(phase: State):
    """From the abort on, every step's commands succeed and the UAV does what it is told."""
    feeds = {
        State.pending: obs(),
        State.checking: obs(),
        State.opening: obs(),
        State.uploading: obs(),
        State.flying: obs(uav_events=["took_off"]),
        State.landing: obs(commands={("uav", "return_to_base"): OK}, uav_landed=True),
        State.confirming: obs(base_events=["landing_confirmed"]),
        State.closing: obs(commands={("base", "close"): OK, ("base", "stop"): OK}),
        State.charging: obs(commands={CHARGE: OK}),
    }
    state, aborting, transition = phase, False, None
    for _ in range(10):
        o = feeds[state]
        transition = advance(state, Observations(**{**o.__dict__, **ABORT}), aborting=aborting)
        if transition is None:  # a step with no abort exit carries on as an aborting run
            aborting = True
            transition = advance(state, o, aborting=True)
        assert transition is not None, state
        aborting = aborting or transition.cause == "operator_abort"
        state = transition.to
        if state in FINAL:
            break
    assert transition is not None and state == State.aborted, (phase, transition)
    flown = phase in (State.landing, State.confirming, State.closing, State.charging)
    verdict = judge(transition, Flight(mission_finished=flown), OK)
    assert (verdict.outcome, verdict.cause, verdict.transition.alert) == (
        RunOutcome.aborted,
        "operator_abort",
        False,
    )


def test_landing_without_mission_finished_is_not_called_mission_finished():
    t = advance(State.flying, obs(uav_events=["took_off", "landing"]))
    assert t is not None and t.to == State.landing and t.cause == "returned_early"
    assert t.reason != "mission finished"
    done = advance(State.flying, obs(uav_events=["took_off", "mission_finished", "landing"]))
    assert done is not None and done.reason == "mission finished" and done.cause == ""


def _run(outcome: str, cause: str | None = None, flight_s: float | None = 60.0) -> Run:
    now = datetime(2026, 12, 7, 12, tzinfo=UTC)
    state = {"completed_with_issues": "completed"}.get(outcome, outcome)
    return Run(
        id=uuid.uuid4(),
        uav_id=uuid.UUID(int=1),
        base_id=uuid.UUID(int=2),
        state=state,
        outcome=outcome,
        cause=cause,
        issues=[cause] if outcome == "completed_with_issues" else [],
        created_at=now,
        flight_started_at=now if flight_s is not None else None,
        flight_time_s=flight_s,
    )


def test_the_fleet_report_counts_only_clean_completions_as_successes():
    """The issue's window: 8 runs, 4 of them having done the job; the report said 0.875."""
    runs = [
        *(_run("completed") for _ in range(4)),
        _run("incomplete", "battery_reserve", 40.0),
        _run("completed_with_issues", RunIssue.charging_refused.value),
        _run("aborted", "not_available", None),
        _run("failed", "landing_not_confirmed"),
    ]
    now = datetime(2026, 12, 7, 13, tzinfo=UTC)
    report = fleet(runs, now - timedelta(days=1), now)
    assert report.success_rate == 0.5
    assert (report.completed, report.completed_with_issues, report.incomplete) == (4, 1, 1)
    assert (report.aborted, report.failed, report.in_progress) == (1, 1, 0)
    assert report.by_outcome == {
        RunOutcome.incomplete: {"battery_reserve": 1},
        RunOutcome.completed_with_issues: {"charging_refused": 1},
        RunOutcome.aborted: {"not_available": 1},
        RunOutcome.failed: {"landing_not_confirmed": 1},
    }
    assert sum(report.failures_by_cause.values()) == 4
    # flight time of the runs that flew, by the UAV's own events (the aborted one never did)
    assert report.mean_flight_time_s == pytest.approx((6 * 60.0 + 40.0) / 7)
