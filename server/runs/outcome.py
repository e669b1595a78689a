"""What a run that has ended achieved: its outcome, cause, issues and alert (pure).

The sequence (machine.py) says where a run stopped; this says whether the job was done.

- `completed`: the mission was flown to its last item (the UAV's own `mission_finished`), the
  UAV landed on the pad (the base's scale confirmed it), the base closed and charging started.
- `completed_with_issues`: the same job done, but with a degradation that did not stop it, named
  in `issues`: `charging_refused` (the charger would not start), `landing_off_contacts` (on the
  lift but off the charging contacts, so charging was refused), `landed_without_precision` (its
  precision landing sent no target while its sensors' readings arrived: it came down on GNSS
  alone). Alert: a person must seat the UAV, see to the charger or check the camera and its
  clock before its next flight.
- `incomplete`: the UAV came back, landed and the base closed, but the mission was not flown to
  its last item; `cause` says why it came home early: `battery_reserve`, `fence_breach`,
  `mission_overrun`, `operator_return` (a person sent the UAV home outside the run),
  `returned_early` (it came home on its own, e.g. its failsafe). Alert, except for an operator's
  return (the person who sent it home knows).
- `aborted`: an operator aborted the run (or the checks refused it before anything moved).
- `failed`: the sequence could not go on; `cause` names the step.

A run is a success (the fleet report's `success_rate`) only when `completed`.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass, replace

from server.runs.machine import CommandOutcome, State, Transition


class RunOutcome(enum.StrEnum):
    """How a finished run ended: whether its job was done (see server/runs/outcome.py)."""

    completed = "completed"
    completed_with_issues = "completed_with_issues"
    incomplete = "incomplete"
    aborted = "aborted"
    failed = "failed"


class RunIssue(enum.StrEnum):
    """A degradation that did not stop the job."""

    charging_refused = "charging_refused"
    landing_off_contacts = "landing_off_contacts"
    landed_without_precision = "landed_without_precision"


# the causes of an `incomplete` run: why the UAV came home before its mission's last item
EARLY_RETURNS = {
    "battery_reserve": "the battery reserve sent it home",
    "fence_breach": "it breached the geofence and its autopilot brought it home",
    "mission_overrun": "it overran the mission's time budget",
    "operator_return": "an operator sent it home",
    "returned_early": "it came home on its own (e.g. its failsafe)",
}
OFF_CONTACTS = "contacts not seated"


@dataclass(frozen=True)
class Flight:
    """What the UAV's own reports and the run's timeline say of its flight."""

    mission_finished: bool = False  # the UAV reported `mission_finished` during the flight
    returned: str = ""  # the cause of the run's flying -> landing step ("": mission finished)
    operator_return: bool = False  # a person sent the UAV `return_to_base` during the flight
    landed_without_precision: bool = False  # it reported landing on GNSS alone, sensors alive


@dataclass(frozen=True)
class Verdict:
    """A final transition with the run's outcome, cause and issues decided."""

    transition: Transition
    outcome: RunOutcome
    cause: str | None
    issues: tuple[RunIssue, ...] = ()


def issues_of(charging: CommandOutcome | None) -> tuple[RunIssue, ...]:
    """The issue a refused or failed `start_charging` leaves: off the contacts, or refused."""
    if charging is None or not charging.final or charging.status == "succeeded":
        return ()
    if OFF_CONTACTS in (charging.reason or "").lower():
        return (RunIssue.landing_off_contacts,)
    return (RunIssue.charging_refused,)


def judge(transition: Transition, flight: Flight, charging: CommandOutcome | None) -> Verdict:
    """The verdict of a transition into a final state.

    The machine ends a run whose sequence ran to its end `completed`; here it stays so only when
    the UAV reported its mission finished, else it becomes `incomplete` with the early return's
    cause. A charging refusal becomes an issue of the outcome instead of its cause.
    """
    issues = issues_of(charging) if transition.cause == "charging_failed" else ()
    if flight.landed_without_precision:
        issues = (*issues, RunIssue.landed_without_precision)
    if transition.to == State.completed:
        if flight.mission_finished:
            if not issues:
                return Verdict(transition, RunOutcome.completed, None, issues)
            flagged = replace(transition, alert=True)  # a person must look before it flies again
            return Verdict(flagged, RunOutcome.completed_with_issues, issues[0].value, issues)
        cause: str = flight.returned or "returned_early"
        if cause == "returned_early" and flight.operator_return:
            cause = "operator_return"
        why = EARLY_RETURNS.get(cause, cause)
        back = transition.reason if issues else "the UAV is back on the pad and charging"
        moved = Transition(
            State.incomplete,
            f"the mission was not flown to its last item: {why}; {back}",
            cause,
            alert=transition.alert or cause != "operator_return",
            extra_actions=transition.extra_actions,
        )
        return Verdict(moved, RunOutcome.incomplete, cause, issues)
    outcome = RunOutcome(transition.to.value)
    final_cause = transition.cause or None
    if outcome == RunOutcome.aborted and issues:  # the aborting run's charging was refused
        final_cause = "operator_abort"
    return Verdict(transition, outcome, final_cause, issues)
