"""The run state machine as a table: every step's success, failure and timeout exit, and aborts."""

from __future__ import annotations

import pytest

from protocol.vocabulary import AvailabilityCondition, AvailabilityReport, Close
from server.runs.machine import (
    FINAL,
    STEPS,
    CommandOutcome,
    Observations,
    State,
    advance,
    on_the_lift,
)


def obs(**kw):  # type: ignore[no-untyped-def]
    base = dict(elapsed_s=1.0, timeout_s=60.0, commands={})
    base.update(kw)
    return Observations(**base)


OK = CommandOutcome("succeeded")


def test_the_happy_path_walks_the_whole_sequence():
    path = [State.pending]
    feeds = {
        State.pending: obs(),
        State.checking: obs(
            commands={("base", "check_availability"): OK, ("uav", "check_availability"): OK}
        ),
        State.opening: obs(commands={("base", "open"): OK}),
        State.uploading: obs(commands={("uav", "upload_mission"): OK}),
        State.flying: obs(
            commands={("uav", "start_mission"): OK},
            uav_events=["armed", "took_off", "mission_finished"],
        ),
        State.landing: obs(commands={("uav", "return_to_base"): OK}, uav_landed=True),
        State.confirming: obs(base_events=["landing_confirmed"]),
        State.closing: obs(commands={("base", "close"): OK}),
        State.charging: obs(commands={("base", "start_charging"): OK}),
    }
    while path[-1] not in FINAL:
        t = advance(path[-1], feeds[path[-1]])
        assert t is not None, path
        path.append(t.to)
    assert path == [
        State.pending,
        State.checking,
        State.opening,
        State.uploading,
        State.flying,
        State.landing,
        State.confirming,
        State.closing,
        State.charging,
        State.completed,
    ]


def test_failed_availability_aborts_listing_every_condition():
    report = AvailabilityReport.of(
        [
            AvailabilityCondition(name="wind", ok=True, value=3.0, limit=8.0, message="wind 3"),
            AvailabilityCondition(
                name="gust", ok=False, value=14.2, limit=12.0,
                message="gust 14.2 m/s over the 12.0 m/s limit",
            ),
            AvailabilityCondition(
                name="rain", ok=False, value=3.1, limit=0.5,
                message="rain 3.1 mm/h over the 0.5 mm/h limit",
            ),
        ]
    )  # fmt: skip
    failed = CommandOutcome("rejected", "not available", report.model_dump(mode="json"))
    t = advance(
        State.checking,
        obs(commands={("base", "check_availability"): failed, ("uav", "check_availability"): OK}),
    )
    assert t is not None and t.to is State.aborted and t.cause == "not_available"
    assert "gust 14.2 m/s over the 12.0 m/s limit" in t.reason and "rain 3.1" in t.reason
    assert not t.extra_actions  # nothing moved, nothing to undo
    assert "wind 3" not in t.reason  # only the failed conditions


def test_an_availability_failure_without_a_report_gives_its_reason():
    failed = CommandOutcome("failed", "PLC link error: timeout", {"unexpected": True})
    t = advance(
        State.checking,
        obs(commands={("base", "check_availability"): failed, ("uav", "check_availability"): OK}),
    )
    assert t is not None and t.to is State.aborted and "PLC link error: timeout" in t.reason


def test_waiting_steps_wait_and_then_time_out():
    assert advance(State.checking, obs(commands={("base", "check_availability"): OK})) is None
    t = advance(State.checking, obs(elapsed_s=61, commands={("base", "check_availability"): OK}))
    assert t is not None and t.to is State.aborted and "the UAV" in t.reason


def test_panel_stall_while_opening_fails_and_closes_the_base():
    t = advance(
        State.opening,
        obs(commands={("base", "open"): CommandOutcome("failed", "panel motor stalled at 40 %")}),
    )
    assert t is not None and t.to is State.failed and "panel motor stalled" in t.reason
    assert [(a.target, a.name) for a in t.extra_actions] == [("base", "close")]


def test_lost_uav_link_in_flight_is_waited_out():
    assert (
        advance(
            State.flying,
            obs(
                elapsed_s=500,
                timeout_s=3600,
                uav_link_up=False,
                commands={("uav", "start_mission"): OK},
                uav_events=["took_off"],
            ),
        )
        is None
    )


def test_mission_overrun_sends_the_uav_home():
    t = advance(State.flying, obs(elapsed_s=3601, timeout_s=3600, uav_events=["took_off"]))
    assert t is not None and t.to is State.landing and t.alert


def test_unconfirmed_landing_fails_and_leaves_the_panels_open():
    t = advance(State.confirming, obs(elapsed_s=91, timeout_s=90, base_mass_g=310.0))
    assert t is not None and t.to is State.failed and t.alert
    assert "310 g" in t.reason and "panels stay open" in t.reason
    assert not any(a.name in ("close", "close_panels") for a in t.extra_actions)


def test_a_landing_the_uav_gave_up_fails_at_once_with_an_alert_and_the_base_open():
    t = advance(State.landing, obs(uav_events=["landing_aborted"]))
    assert t is not None and t.to is State.failed and t.alert and t.cause == "landing_aborted"
    assert "land it by hand" in t.reason and "stays open" in t.reason
    assert not any(a.name in ("close", "close_panels") for a in t.extra_actions)


def test_a_landing_that_came_down_without_precision_goes_on_with_an_alert():
    """The agent's precision landing sent no target while its camera's frames arrived (issue 46):
    the run goes on to the scale, alerted; a landing that steered has no alert."""
    told = ["landed", "landed_without_precision"]
    t = advance(State.landing, obs(uav_events=told, uav_landed=True))
    assert t is not None and t.to is State.confirming and t.alert
    assert t.cause == "landed_without_precision" and "no target" in t.reason
    t = advance(State.landing, obs(uav_events=["landed"], uav_landed=True))
    assert t is not None and t.to is State.confirming and not t.alert


@pytest.mark.parametrize("state", [State.flying, State.landing, State.confirming])
def test_no_failure_after_take_off_closes_the_panels(state):
    for o in (
        obs(elapsed_s=10_000, timeout_s=1, uav_events=["took_off"]),
        obs(
            elapsed_s=10_000,
            timeout_s=1,
            uav_events=["took_off"],
            commands={
                (a.target, a.name): CommandOutcome("failed", "x") for a in STEPS[state].actions
            },
        ),
    ):
        t = advance(state, o)
        if t is not None:
            assert not any(a.name in ("close", "close_panels") for a in t.extra_actions), (
                state,
                t,
            )


@pytest.mark.parametrize(
    ("state", "to", "closes"),
    [
        (State.pending, State.aborted, False),
        (State.checking, State.aborted, False),
        (State.opening, State.closing, True),
        (State.uploading, State.closing, True),
        (State.flying, State.landing, False),
    ],
)
def test_operator_abort_has_the_safe_outcome_of_each_step(state, to, closes):
    t = advance(state, obs(abort_requested=True, abort_reason="bird strike risk"))
    assert (
        t is not None
        and t.to is to
        and t.cause == "operator_abort"
        and "bird strike risk" in t.reason
    )
    assert (State.closing is t.to) == closes


def test_an_aborted_run_that_gets_home_ends_aborted():
    t = advance(State.charging, obs(commands={("base", "start_charging"): OK}), aborting=True)
    assert t is not None and t.to is State.aborted


def test_takeoff_failure_closes_the_base_while_the_uav_is_still_on_the_lift():
    t = advance(
        State.flying,
        obs(
            commands={("uav", "start_mission"): CommandOutcome("failed", "PreArm: GPS")},
            uav_landed=True,
        ),
    )
    assert t is not None and t.to is State.failed and [a.name for a in t.extra_actions] == ["close"]
    # without telemetry showing the UAV disarmed on the lift, nothing closes
    t = advance(
        State.flying,
        obs(commands={("uav", "start_mission"): CommandOutcome("failed", "PreArm: GPS")}),
    )
    assert t is not None and t.to is State.failed and not t.extra_actions and t.alert


def test_a_landing_confirmed_before_the_step_began_is_read_from_the_base_state():
    """The base may confirm while the UAV's own 'landed' is still on its way (e.g. after a reconnect)."""
    t = advance(State.confirming, obs(base_confirms=True))
    assert t is not None and t.to is State.closing


def _closes(exit_) -> bool:  # type: ignore[no-untyped-def]
    return exit_.to is State.closing or any(a.command is Close for a in exit_.safe)


def test_the_table_reads_as_the_safety_policy():
    """The module docstring's rules, read off the table itself rather than from examples."""
    before_take_off = (State.opening, State.uploading)
    for state in before_take_off:
        step = STEPS[state]
        # a failure, a timeout or an abort with the UAV on the lift closes the base
        assert all(_closes(e) for e in (*step.failure, *step.timeout, *step.abort)), state
    for state in (State.landing, State.confirming):
        step = STEPS[state]
        exits = (*step.done, *step.failure, *step.timeout, *step.abort)
        # after take-off nothing closes until the scale confirms; an abort is finished safely
        assert not any(any(a.command is Close for a in e.safe) for e in exits), state
        assert not step.abort, state
    # in flight, only a start that never left the lift closes the base
    assert [e.when for e in STEPS[State.flying].failure if _closes(e)] == [on_the_lift]
    assert [e.to for e in STEPS[State.flying].abort] == [State.landing]
    assert STEPS[State.confirming].done[0].to is State.closing
    # every step but the final ones has a way out on time
    assert all(STEPS[s].timeout for s in State if s not in FINAL and s is not State.pending)


@pytest.mark.parametrize(
    ("state", "feed", "to"),
    [
        (State.landing, {"uav_landed": True}, State.confirming),
        (State.landing, {"elapsed_s": 901, "timeout_s": 900}, State.failed),
        (State.confirming, {"base_confirms": True}, State.closing),
        (State.closing, {"commands": {("base", "close"): OK}}, State.charging),
        (State.charging, {"commands": {("base", "start_charging"): OK}}, State.aborted),
    ],
)
def test_an_abort_after_take_off_lets_the_run_finish_safely_and_end_aborted(state, feed, to):
    """Already heading home: the abort neither freezes the run nor closes anything early."""
    t = advance(state, obs(abort_requested=True, abort_reason="fog", **feed))
    assert t is not None and t.to is to
    if to is State.aborted:
        assert t.cause == "operator_abort"


def test_a_silent_base_is_waited_for_before_the_scale_is_judged():
    """Issue 14 #6: after a server restart the UAV's link came back first; its landing moved the run
    to confirming while the base was still reconnecting, and the step timed out on a scale that had
    not reported at all ('landing_not_confirmed', panels left open). Silence is no verdict."""
    late = dict(elapsed_s=61.0, timeout_s=60.0, commands={})
    assert advance(State.confirming, obs(**late, base_heard=False)) is None  # waiting for the base
    heard = advance(State.confirming, obs(**late, base_heard=True, base_mass_g=3.0))
    assert heard is not None and heard.cause == "landing_not_confirmed" and heard.alert
    back = advance(State.confirming, obs(**late, base_heard=True, base_confirms=True))
    assert back is not None and back.to is State.closing
    gone = advance(State.confirming, obs(elapsed_s=301.0, timeout_s=60.0, base_heard=False))
    assert gone is not None and gone.cause == "base_silent" and gone.alert
    assert "panels stay open" in gone.reason
