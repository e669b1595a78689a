"""A failed run's "the base is being closed" becomes what happened once the close has ended.

Issue 14 #4: a run failed while opening said "the base is being closed", the base refused the
close (its PLC had latched a fault) and nobody was told. The verdict is pure (settle.py); the
engine records it (tests/e2e/test_base_recovery.py drives it against the real daemons).
"""

from __future__ import annotations

from server.runs.machine import (
    BEING_CLOSED,
    FINAL,
    STEPS,
    CommandOutcome,
    Observations,
    State,
    advance,
)
from server.runs.settle import settle


def _failed_opening() -> str:
    t = advance(
        State.opening,
        Observations(
            elapsed_s=1.0,
            timeout_s=60.0,
            commands={
                ("base", "open"): CommandOutcome("failed", "interrupted: the agent restarted")
            },
        ),
    )
    assert t is not None and t.to is State.failed and BEING_CLOSED in t.reason
    return t.reason


def test_a_close_that_succeeded_says_the_base_is_closed_without_alert() -> None:
    reason = _failed_opening()
    done = settle(reason, {("base", "close"): CommandOutcome("succeeded", "base closed")})
    assert done is not None and not done.alert and done.cause == "safe_state_reached"
    assert BEING_CLOSED not in done.reason and "the base is closed" in done.reason
    assert done.reason.startswith("opening the base failed at the base")


def test_a_refused_close_raises_an_alert_and_says_why() -> None:
    reason = _failed_opening()
    refused = CommandOutcome("rejected", "lift down refused: faults latched: WATCHDOG")
    done = settle(reason, {("base", "close"): refused})
    assert done is not None and done.alert and done.cause == "safe_state_not_reached"
    assert BEING_CLOSED not in done.reason
    assert "could not be closed" in done.reason and "WATCHDOG" in done.reason
    assert "a person must look" in done.note


def test_a_close_that_never_came_back_is_an_alert_too() -> None:
    done = settle(
        "x; " + BEING_CLOSED, {("base", "stop"): CommandOutcome("succeeded"),
                              ("base", "close"): CommandOutcome("timed_out")}
    )  # fmt: skip
    assert done is not None and done.alert and "timed_out" in done.reason


def test_a_failed_stop_before_a_successful_close_is_no_alert() -> None:
    done = settle(
        BEING_CLOSED, {("base", "stop"): CommandOutcome("failed", "PLC link down"),
                       ("base", "close"): CommandOutcome("succeeded")}
    )  # fmt: skip
    assert done is not None and not done.alert and done.reason == "the base is closed"


def test_nothing_is_said_while_a_safe_command_runs() -> None:
    assert settle(BEING_CLOSED, {("base", "close"): CommandOutcome("in_progress")}) is None
    assert settle(BEING_CLOSED, {}) is None


def test_every_final_exit_that_closes_the_base_says_so_in_the_words_settle_rewrites() -> None:
    closing_exits = [
        e
        for step in STEPS.values()
        for e in (*step.done, *step.failure, *step.timeout, *step.abort)
        if e.to in FINAL and any(a.name == "close" for a in e.safe)
    ]
    assert len(closing_exits) >= 5
    assert all(BEING_CLOSED in e.reason for e in closing_exits)
