"""The autonomous sequence as one table and one pure function.

A run walks the ALPHA base's sequence (Moreira et al. 2021, Fig. 8):

    pending → checking → opening → uploading → flying → landing → confirming → closing → charging → completed

Each step has: what is commanded on entry, what completes it, how long it may take, and where it
goes on failure. `advance` looks at what has been observed since the step began and returns the
next transition (or None to keep waiting). It does no I/O: the engine persists the transition
first, then issues the commands the new step names.

Safety rules encoded here:
- before take-off, a failure closes the base (the UAV is on the lift: the check saw it on the scale);
- after take-off, nothing closes the panels until the scale has confirmed the UAV on the lift;
- an operator abort before take-off closes the base; in flight it returns the UAV to the base and lands.
"""

from __future__ import annotations

import enum
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from protocol.vocabulary import (
    FINAL_STATUSES,
    AvailabilityReport,
    CheckAvailability,
    Close,
    CommandParams,
    CommandStatus,
    Open,
    ReturnToBase,
    StartCharging,
    StartMission,
    Stop,
    UploadMission,
)


class State(enum.StrEnum):
    """Where a run stands."""

    pending = "pending"
    checking = "checking"
    opening = "opening"
    uploading = "uploading"
    flying = "flying"
    landing = "landing"
    confirming = "confirming"
    closing = "closing"
    charging = "charging"
    completed = "completed"
    aborted = "aborted"
    failed = "failed"


FINAL = frozenset({State.completed, State.aborted, State.failed})
AIRBORNE = frozenset({State.flying, State.landing})


@dataclass(frozen=True)
class Action:
    """A command to issue on entering a step: to the `base` or the `uav`.

    `command` is the command's model; the engine fills in its params (the mission's items, the
    UAV's mass) when it issues it.
    """

    target: str  # "base" | "uav"
    command: type[CommandParams]

    @property
    def name(self) -> str:
        """The command's name on the wire."""
        return self.command.name

    @property
    def key(self) -> str:
        """``target:name``, how a run records the command it issued for this action."""
        return f"{self.target}:{self.command.name}"


@dataclass(frozen=True)
class Step:
    """One row of the sequence table."""

    state: State
    number: int
    label: str
    actions: tuple[Action, ...]
    default_timeout_s: float


STEPS: dict[State, Step] = {
    s.state: s
    for s in (
        Step(State.pending, 0, "Waiting to start", (), 30),
        Step(
            State.checking,
            1,
            "Checking weather, base health and UAV readiness",
            (Action("base", CheckAvailability), Action("uav", CheckAvailability)),
            60,
        ),
        Step(
            State.opening,
            2,
            "Opening the base (side panels, then lift up)",
            (Action("base", Open),),
            120,
        ),
        Step(
            State.uploading,
            3,
            "Uploading the mission to the UAV and reading it back",
            (Action("uav", UploadMission),),
            90,
        ),
        Step(State.flying, 4, "Flying the mission", (Action("uav", StartMission),), 3600),
        Step(
            State.landing,
            5,
            "Returning to the base and landing on the pad",
            (Action("uav", ReturnToBase),),
            900,
        ),
        Step(State.confirming, 6, "Confirming the landing on the base's scale", (), 90),
        Step(
            State.closing,
            7,
            "Closing the base (lift down, then side panels)",
            (Action("base", Close),),
            120,
        ),
        Step(State.charging, 8, "Starting to charge the UAV", (Action("base", StartCharging),), 60),
        Step(State.completed, 9, "Completed", (), 0),
        Step(State.aborted, 9, "Aborted", (), 0),
        Step(State.failed, 9, "Failed", (), 0),
    )
}
TOTAL_STEPS = 8


@dataclass(frozen=True)
class CommandOutcome:
    """What became of a command the step issued."""

    status: CommandStatus | str
    reason: str = ""
    data: Mapping[str, Any] | None = None

    @property
    def final(self) -> bool:
        """True once the command has ended."""
        return self.status in FINAL_STATUSES


@dataclass(frozen=True)
class Observations:
    """Everything the machine may look at, gathered since the current step began."""

    elapsed_s: float
    timeout_s: float
    commands: Mapping[tuple[str, str], CommandOutcome]  # (target, command) -> outcome
    uav_events: Sequence[str] = ()
    base_events: Sequence[str] = ()
    uav_landed: bool = False  # on the ground and disarmed, per telemetry
    uav_link_up: bool = True
    base_mass_g: float | None = None
    base_confirms: bool = (
        False  # the base's latest telemetry (sent after this step began) says confirmed
    )
    abort_requested: bool = False
    abort_reason: str = ""
    took_off: bool = False


@dataclass(frozen=True)
class Transition:
    """Go to `to` because of `reason`; `cause` is a short code for reports, `safe` what was done."""

    to: State
    reason: str
    cause: str = ""
    alert: bool = (
        False  # operators must look at this (UAV or base left in a state that needs a person)
    )
    extra_actions: tuple[Action, ...] = ()


def _failed_conditions(outcome: CommandOutcome) -> str:
    try:
        summary = AvailabilityReport.model_validate(outcome.data or {}).summary
    except ValueError:  # no report (e.g. the command failed before checking): its reason says why
        summary = ""
    return summary or outcome.reason or outcome.status


def _command_failure(
    step: Step, outcomes: Mapping[tuple[str, str], CommandOutcome]
) -> tuple[Action, CommandOutcome] | None:
    for action in step.actions:
        outcome = outcomes.get((action.target, action.name))
        if outcome and outcome.final and outcome.status != "succeeded":
            return action, outcome
    return None


def _all_succeeded(step: Step, outcomes: Mapping[tuple[str, str], CommandOutcome]) -> bool:
    return all(
        (o := outcomes.get((a.target, a.name))) is not None and o.status == "succeeded"
        for a in step.actions
    )


WHO = {"base": "the base", "uav": "the UAV"}


def advance(state: State, obs: Observations, *, aborting: bool = False) -> Transition | None:
    """The next transition of a run in `state`, or None to keep waiting."""
    if state in FINAL:
        return None
    step = STEPS[state]
    # 1. operator abort: the safe outcome depends on where the run stands
    if obs.abort_requested and not aborting:
        why = (
            f"aborted by an operator: {obs.abort_reason}"
            if obs.abort_reason
            else "aborted by an operator"
        )
        if state in (State.pending, State.checking):
            return Transition(State.aborted, f"{why}; nothing had moved", "operator_abort")
        if state in (State.opening, State.uploading):
            return Transition(
                State.closing,
                f"{why}; closing the base (the UAV is still on the lift)",
                "operator_abort",
                extra_actions=(Action("base", Stop),),
            )
        if state is State.flying:
            return Transition(
                State.landing, f"{why}; returning the UAV to the base to land", "operator_abort"
            )
        return None  # landing, confirming, closing, charging: already heading home; finish safely
    failure = _command_failure(step, obs.commands)
    if state is State.pending:
        return Transition(State.checking, "run started")
    if state is State.checking:
        if failure:
            action, outcome = failure
            return Transition(
                State.aborted,
                f"{WHO[action.target]} is not available: {_failed_conditions(outcome)}",
                "not_available",
            )
        if _all_succeeded(step, obs.commands):
            return Transition(State.opening, "weather, base and UAV are all within limits")
        if obs.elapsed_s > obs.timeout_s:
            missing = [
                WHO[a.target]
                for a in step.actions
                if not (o := obs.commands.get((a.target, a.name))) or not o.final
            ]
            return Transition(
                State.aborted,
                f"no availability answer from {' and '.join(missing)} within {obs.timeout_s:.0f} s",
                "check_timeout",
            )
        return None
    if state in (State.opening, State.uploading):
        if failure:
            action, outcome = failure
            what = "opening the base" if state is State.opening else "uploading the mission"
            return Transition(
                State.failed,
                f"{what} failed at {WHO[action.target]}: {outcome.reason or outcome.status}; "
                "the base is being closed (the UAV never left the lift)",
                f"{state.value}_failed",
                extra_actions=(Action("base", Close),),
            )
        if _all_succeeded(step, obs.commands):
            nxt = State.uploading if state is State.opening else State.flying
            return Transition(
                nxt,
                "base open, lift up" if state is State.opening else "mission uploaded and verified",
            )
        if obs.elapsed_s > obs.timeout_s:
            return Transition(
                State.failed,
                f"{step.label.lower()} did not finish within {obs.timeout_s:.0f} s; "
                "the base is being closed",
                f"{state.value}_timeout",
                extra_actions=(Action("base", Stop), Action("base", Close)),
            )
        return None
    if state is State.flying:
        took_off = obs.took_off or "took_off" in obs.uav_events
        if failure:
            _, outcome = failure
            why = f"the UAV could not start the mission: {outcome.reason or outcome.status}"
            if not took_off and obs.uav_landed:
                return Transition(
                    State.failed,
                    f"{why}; it is on the lift, disarmed: the base is being closed",
                    "takeoff_failed",
                    extra_actions=(Action("base", Close),),
                )
            if not took_off:
                return Transition(
                    State.failed,
                    f"{why}; the UAV's state is unknown, so the base stays open",
                    "takeoff_failed",
                    alert=True,
                )
        if {"mission_finished", "landing", "landed"} & set(obs.uav_events):
            return Transition(State.landing, "mission finished")
        if obs.elapsed_s > obs.timeout_s:
            return Transition(
                State.landing,
                f"the mission overran its {obs.timeout_s:.0f} s budget; returning to the base",
                "mission_overrun",
                alert=True,
            )
        return None  # a lost UAV link is waited out: the autopilot flies the mission on its own
    if state is State.landing:
        if obs.uav_landed or "landed" in obs.uav_events:
            return Transition(State.confirming, "the UAV reports it has landed")
        if obs.elapsed_s > obs.timeout_s:
            return Transition(
                State.failed,
                f"the UAV has not landed within {obs.timeout_s:.0f} s of heading home; "
                "the base stays open",
                "landing_timeout",
                alert=True,
            )
        return None
    if state is State.confirming:
        if "landing_confirmed" in obs.base_events or obs.base_confirms:
            return Transition(State.closing, "the base's scale confirms the UAV on the lift")
        if obs.elapsed_s > obs.timeout_s:
            mass = f"{obs.base_mass_g:.0f} g" if obs.base_mass_g is not None else "no reading"
            return Transition(
                State.failed,
                f"the scale did not confirm the UAV within {obs.timeout_s:.0f} s "
                f"(scale reads {mass}); the UAV may be off the pad, the panels stay open",
                "landing_not_confirmed",
                alert=True,
            )
        return None
    if state in (State.closing, State.charging):
        final_ok = State.aborted if aborting else State.completed
        if failure:
            action, outcome = failure
            if state is State.charging:
                return Transition(
                    final_ok,
                    f"the base is closed but charging did not start: "
                    f"{outcome.reason or outcome.status}",
                    "charging_failed",
                    alert=True,
                )
            return Transition(
                State.failed,
                f"closing the base failed: {outcome.reason or outcome.status}",
                "closing_failed",
                alert=True,
            )
        if _all_succeeded(step, obs.commands):
            if state is State.closing:
                return Transition(State.charging, "base closed")
            return Transition(
                final_ok,
                "charging; the run is over"
                if not aborting
                else "the UAV is back and charging; the run was aborted by an operator",
                "operator_abort" if aborting else "",
            )
        if obs.elapsed_s > obs.timeout_s:
            return Transition(
                State.failed,
                f"{step.label.lower()} did not finish within {obs.timeout_s:.0f} s",
                f"{state.value}_timeout",
                alert=True,
            )
        return None
    return None
