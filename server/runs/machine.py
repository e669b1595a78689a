"""The autonomous sequence as one table and one pure function.

A run walks the ALPHA base's sequence (Moreira et al. 2021, Fig. 8):

    pending → checking → opening → uploading → flying → landing → confirming → closing → charging → completed

Each step (a row of `STEPS`) names what is commanded on entry and its exits: `done` (a
completion predicate holds), `failure` (a command of the step ended without success),
`timeout` (the step's time budget ran out) and `abort` (an operator asked to stop). An exit
says where the run goes, why, with what short cause, whether a person must look (`alert`) and
which commands are issued on the way out (`safe`). `advance` is a generic evaluator over that
table: it looks at what has been observed since the step began and returns the next transition
(or None to keep waiting). It does no I/O: the engine persists the transition first, then issues
the commands the exit and the new step name.

The safety policy, as the table encodes it:
- before take-off, a failure closes the base (the UAV is on the lift: the check saw it on the scale);
- after take-off, nothing closes the panels until the scale has confirmed the UAV on the lift;
- an operator abort before take-off closes the base; in flight it returns the UAV to the base and lands.

Long because: the sequence table and its exits are the safety policy, and it must read in one
place; the evaluator and the predicates around it are short.
"""

from __future__ import annotations

import enum
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any, Literal

from protocol.vocabulary import (
    FINAL_STATUSES,
    AvailabilityReport,
    CheckAvailability,
    Close,
    CommandParams,
    CommandStatus,
    Land,
    Open,
    ReturnToBase,
    StartCharging,
    StartMission,
    Stop,
    UploadMission,
)


class RunState(enum.StrEnum):
    """Where a run stands: `pending`, then the eight steps `checking` … `charging`, then one of
    the final states `completed`, `incomplete`, `aborted`, `failed` (outcome.py decides between
    `completed` and `incomplete` once the sequence has run to its end)."""

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
    incomplete = "incomplete"
    aborted = "aborted"
    failed = "failed"


State = RunState  # the engine's short name

FINAL = frozenset({State.completed, State.incomplete, State.aborted, State.failed})
AIRBORNE = frozenset({State.flying, State.landing})
TOTAL_STEPS = 8
Target = Literal["base", "uav"]
WHO: dict[str, str] = {"base": "the base", "uav": "the UAV"}


@dataclass(frozen=True)
class Action:
    """A command to issue on entering a step: to the `base` or the `uav`.

    `command` is the command's model; the engine fills in its params (the mission's items, the
    UAV's mass) when it issues it.
    """

    target: Target
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
    base_heard: bool = True  # the base has sent telemetry since this step began
    abort_requested: bool = False
    abort_reason: str = ""
    took_off: bool = False
    airspace: str = ""  # why the mission's path breaks the airspace now ("": it does not)
    return_margin_pct: float | None = None  # battery left above the reserve after going home now
    # flying home now would land with less than the critical level (reserve.py), what it would
    # cost and what the battery holds (percent)
    home_out_of_reach: bool = False
    home_need_pct: float | None = None
    battery_pct: float | None = None


@dataclass(frozen=True)
class Transition:
    """Go to `to` because of `reason`; `cause` is a short code for reports."""

    to: State
    reason: str
    cause: str = ""
    alert: bool = (
        False  # operators must look at this (UAV or base left in a state that needs a person)
    )
    extra_actions: tuple[Action, ...] = ()


# --- what a step has seen, and the predicates over it ---------------------------------


@dataclass(frozen=True)
class Seen:
    """The context an exit is judged in: the step, the observations, the failed command."""

    step: Step
    obs: Observations
    aborting: bool
    failure: tuple[Action, CommandOutcome] | None

    def words(self) -> dict[str, str]:
        """The fields an exit's reason may name, e.g. ``{timeout}`` or ``{failure}``."""
        obs, step = self.obs, self.step
        action, outcome = self.failure or (None, None)
        missing = [
            WHO[a.target]
            for a in step.actions
            if not (o := obs.commands.get((a.target, a.name))) or not o.final
        ]
        why = "aborted by an operator"
        return {
            "why": f"{why}: {obs.abort_reason}" if obs.abort_reason else why,
            "who": WHO[action.target] if action else "",
            "failure": (outcome.reason or outcome.status) if outcome else "",
            "conditions": _failed_conditions(outcome) if outcome else "",
            "timeout": f"{obs.timeout_s:.0f}",
            "label": step.label.lower(),
            "missing": " and ".join(missing),
            "mass": f"{obs.base_mass_g:.0f} g" if obs.base_mass_g is not None else "no reading",
            "airspace": obs.airspace,
            "margin": f"{obs.return_margin_pct:.1f}" if obs.return_margin_pct is not None else "",
            "need": f"{obs.home_need_pct:.0f}" if obs.home_need_pct is not None else "?",
            "battery": f"{obs.battery_pct:.0f}" if obs.battery_pct is not None else "?",
            "left": (
                f"{obs.battery_pct - obs.home_need_pct:.0f}"
                if obs.battery_pct is not None and obs.home_need_pct is not None
                else "?"
            ),
        }


Guard = Callable[[Seen], bool]


def always(seen: Seen) -> bool:
    """Every time."""
    return True


def all_succeeded(seen: Seen) -> bool:
    """Every command of the step succeeded."""
    return all(
        (o := seen.obs.commands.get((a.target, a.name))) is not None and o.status == "succeeded"
        for a in seen.step.actions
    )


def took_off(seen: Seen) -> bool:
    """The UAV has left the lift."""
    return seen.obs.took_off or "took_off" in seen.obs.uav_events


def on_the_lift(seen: Seen) -> bool:
    """Not taken off, and telemetry shows it disarmed on the ground: still on the lift."""
    return not took_off(seen) and seen.obs.uav_landed


def mission_finished(seen: Seen) -> bool:
    """The UAV reports its mission flown to its last item (its own `mission_finished`)."""
    return "mission_finished" in seen.obs.uav_events


def coming_down_early(seen: Seen) -> bool:
    """The UAV is landing (or has landed) without having reported its mission finished: it was
    sent home outside this run (an operator's return, its own failsafe)."""
    return bool({"landing", "landed"} & set(seen.obs.uav_events))


def uav_landed(seen: Seen) -> bool:
    """The UAV reports it has landed."""
    return seen.obs.uav_landed or "landed" in seen.obs.uav_events


def landed_without_precision(seen: Seen) -> bool:
    """The agent says its precision landing watched the pad's sensors and sent no target."""
    return "landed_without_precision" in seen.obs.uav_events


def landing_abandoned(seen: Seen) -> bool:
    """The UAV gave its landing up (no pad found or lost without RTK fixed GNSS to land on, or
    held off the pad by the wind): it holds up."""
    return "landing_aborted" in seen.obs.uav_events


def airspace_refused(seen: Seen) -> bool:
    """The mission's path breaks a zone active now (checked again at the start: zones change)."""
    return bool(seen.obs.airspace)


def reserve_reached(seen: Seen) -> bool:
    """Going home now would leave no more than the battery reserve (reserve.py)."""
    margin = seen.obs.return_margin_pct
    return margin is not None and margin <= 0 and took_off(seen)


def home_out_of_reach(seen: Seen) -> bool:
    """Flying home now would land with less than the critical battery level, the UAV still in
    the air (the step's: it follows the flight; a UAV that has landed is where it is)."""
    return seen.obs.home_out_of_reach and not seen.obs.uav_landed


def fence_breached(seen: Seen) -> bool:
    """The UAV's autopilot reports a geofence breach (it has switched to RTL on its own)."""
    return "fence_breach" in seen.obs.uav_events


def scale_confirms(seen: Seen) -> bool:
    """The base's scale confirms the UAV on the lift."""
    return "landing_confirmed" in seen.obs.base_events or seen.obs.base_confirms


def base_heard(seen: Seen) -> bool:
    """The base has reported since the step began: its scale's silence means something."""
    return seen.obs.base_heard


def base_silent_too_long(seen: Seen) -> bool:
    """The base has said nothing since the step began, for five times the step's budget."""
    return not seen.obs.base_heard and seen.obs.elapsed_s > 5 * seen.obs.timeout_s


def aborting(seen: Seen) -> bool:
    """An operator's abort is being carried out."""
    return seen.aborting


def both(a: Guard, b: Guard) -> Guard:
    """A guard holding when `a` and `b` do."""
    return lambda seen: a(seen) and b(seen)


def negate(a: Guard) -> Guard:
    """A guard holding when `a` does not."""
    return lambda seen: not a(seen)


# --- the table ------------------------------------------------------------------------


@dataclass(frozen=True)
class Exit:
    """A way out of a step, taken when `when` holds; `reason` is formatted by `Seen.words`."""

    to: State
    reason: str
    cause: str = ""
    alert: bool = False
    safe: tuple[Action, ...] = ()  # issued on the way out, before the new step's own actions
    when: Guard = always

    def take(self, seen: Seen) -> Transition:
        """The transition of this exit in this context."""
        return Transition(
            self.to, self.reason.format(**seen.words()), self.cause, self.alert, self.safe
        )


@dataclass(frozen=True)
class Step:
    """One row of the sequence table: entry actions, time budget and the four kinds of exit."""

    state: State
    number: int
    label: str
    actions: tuple[Action, ...] = ()
    default_timeout_s: float = 0
    done: tuple[Exit, ...] = ()
    failure: tuple[Exit, ...] = ()
    timeout: tuple[Exit, ...] = ()
    abort: tuple[Exit, ...] = ()  # none: already heading home, the run finishes safely


CLOSE, STOP = Action("base", Close), Action("base", Stop)
LAND_HERE = Action("uav", Land)  # the contingency when home is out of reach
ABORT_NOTHING_MOVED = Exit(State.aborted, "{why}; nothing had moved", "operator_abort")
ABORT_ON_THE_LIFT = Exit(
    State.closing,
    "{why}; closing the base (the UAV is still on the lift)",
    "operator_abort",
    safe=(STOP,),
)
CHARGING_FAILED = "the base is closed but charging did not start: {failure}"
# said when a failure closes the base on its way out; settle.py rewrites it to what happened
BEING_CLOSED = "the base is being closed"

STEPS: dict[State, Step] = {
    s.state: s
    for s in (
        Step(
            State.pending, 0, "Waiting to start", default_timeout_s=30,
            done=(Exit(State.checking, "run started"),),
            abort=(ABORT_NOTHING_MOVED,),
        ),
        Step(
            State.checking, 1, "Checking weather, base and UAV readiness",
            (Action("base", CheckAvailability), Action("uav", CheckAvailability)), 60,
            done=(
                Exit(State.aborted, "the mission's path breaks the airspace: {airspace}",
                     "airspace", when=airspace_refused),
                Exit(State.opening, "weather, base and UAV are all within limits",
                     when=all_succeeded),
            ),
            failure=(Exit(State.aborted, "{who} is not available: {conditions}", "not_available"),),
            timeout=(
                Exit(State.aborted, "no availability answer from {missing} within {timeout} s",
                     "check_timeout"),
            ),
            abort=(ABORT_NOTHING_MOVED,),
        ),
        Step(
            State.opening, 2, "Opening the base (side panels, then lift up)",
            (Action("base", Open),), 120,
            done=(Exit(State.uploading, "base open, lift up", when=all_succeeded),),
            failure=(
                Exit(State.failed, "opening the base failed at {who}: {failure}; "
                     "the base is being closed (the UAV never left the lift)",
                     "opening_failed", safe=(CLOSE,)),
            ),
            timeout=(
                Exit(State.failed, "{label} did not finish within {timeout} s; "
                     "the base is being closed", "opening_timeout", safe=(STOP, CLOSE)),
            ),
            abort=(ABORT_ON_THE_LIFT,),
        ),
        Step(
            State.uploading, 3, "Uploading the mission to the UAV and reading it back",
            (Action("uav", UploadMission),), 90,
            done=(Exit(State.flying, "mission uploaded and verified", when=all_succeeded),),
            failure=(
                Exit(State.failed, "uploading the mission failed at {who}: {failure}; "
                     "the base is being closed (the UAV never left the lift)",
                     "uploading_failed", safe=(CLOSE,)),
            ),
            timeout=(
                Exit(State.failed, "{label} did not finish within {timeout} s; "
                     "the base is being closed", "uploading_timeout", safe=(STOP, CLOSE)),
            ),
            abort=(ABORT_ON_THE_LIFT,),
        ),
        Step(
            State.flying, 4, "Flying the mission", (Action("uav", StartMission),), 3600,
            done=(
                Exit(State.landing, "the UAV breached the geofence: its autopilot is returning "
                     "it to the base; landing there", "fence_breach", alert=True,
                     when=fence_breached),
                Exit(State.landing, "mission finished", when=mission_finished),
                Exit(State.landing, "the UAV is landing before reporting its mission finished "
                     "(sent home outside this run: an operator's return or its own failsafe)",
                     "returned_early", when=coming_down_early),
                Exit(State.landing, "the battery is at its return reserve (margin {margin} % "
                     "after flying home against the wind); returning to the base",
                     "battery_reserve", alert=True, when=reserve_reached),
            ),
            # once it has taken off, a failed start is not a failure: the mission is flying
            failure=(
                Exit(State.failed, "the UAV could not start the mission: {failure}; "
                     "it is on the lift, disarmed: the base is being closed",
                     "takeoff_failed", safe=(CLOSE,), when=on_the_lift),
                Exit(State.failed, "the UAV could not start the mission: {failure}; "
                     "the UAV's state is unknown, so the base stays open",
                     "takeoff_failed", alert=True, when=negate(took_off)),
            ),
            # a lost UAV link is waited out: the autopilot flies the mission on its own
            timeout=(
                Exit(State.landing, "the mission overran its {timeout} s budget; "
                     "returning to the base", "mission_overrun", alert=True),
            ),
            abort=(
                Exit(State.landing, "{why}; returning the UAV to the base to land",
                     "operator_abort"),
            ),
        ),
        Step(
            State.landing, 5, "Returning to the base and landing on the pad",
            (Action("uav", ReturnToBase),), 900,
            done=(
                Exit(State.confirming, "the UAV reports it has landed on GNSS alone: its "
                     "precision landing sent no target while its camera's frames arrived; check "
                     "the camera and its clock", "landed_without_precision", alert=True,
                     when=both(uav_landed, landed_without_precision)),
                Exit(State.confirming, "the UAV reports it has landed", when=uav_landed),
                Exit(State.failed, "the UAV cannot reach its base: flying home against the "
                     "wind the base measures would take {need} % of its {battery} % and land it "
                     "with {left} %, under its critical level; it is landing where it is — "
                     "recover it there",
                     "home_out_of_reach", alert=True, safe=(LAND_HERE,),
                     when=home_out_of_reach),
                Exit(State.failed, "the UAV gave up its landing: the pad was not found (or lost "
                     "too high with its retries used up) and its GNSS has no RTK fix to land "
                     "on, or the wind held it off the pad; it climbed and holds there; the base "
                     "stays open — land it by hand", "landing_aborted", alert=True,
                     when=landing_abandoned),
            ),
            timeout=(
                Exit(State.failed, "the UAV has not landed within {timeout} s of heading home; "
                     "the base stays open", "landing_timeout", alert=True),
            ),
        ),
        Step(
            State.confirming, 6, "Confirming the landing on the base's scale",
            default_timeout_s=90,
            done=(
                Exit(State.closing, "the base's scale confirms the UAV on the lift",
                     when=scale_confirms),
            ),
            # a base that has not reported since (its link is coming back after a server restart
            # or a cut) is waited for: its scale's silence is no verdict
            timeout=(
                Exit(State.failed, "the scale did not confirm the UAV within {timeout} s "
                     "(scale reads {mass}); the UAV may be off the pad, the panels stay open",
                     "landing_not_confirmed", alert=True, when=base_heard),
                Exit(State.failed, "the base has sent nothing since the UAV landed, so its "
                     "scale cannot confirm the landing; the panels stay open",
                     "base_silent", alert=True, when=base_silent_too_long),
            ),
        ),
        Step(
            State.closing, 7, "Closing the base (lift down, then side panels)",
            (CLOSE,), 120,
            done=(Exit(State.charging, "base closed", when=all_succeeded),),
            failure=(
                Exit(State.failed, "closing the base failed: {failure}", "closing_failed",
                     alert=True),
            ),
            timeout=(
                Exit(State.failed, "{label} did not finish within {timeout} s",
                     "closing_timeout", alert=True),
            ),
        ),
        Step(
            State.charging, 8, "Starting to charge the UAV",
            (Action("base", StartCharging),), 60,
            done=(
                Exit(State.aborted, "the UAV is back and charging; "
                     "the run was aborted by an operator", "operator_abort",
                     when=both(all_succeeded, aborting)),
                Exit(State.completed, "charging; the run is over", when=all_succeeded),
            ),
            failure=(
                Exit(State.aborted, CHARGING_FAILED, "charging_failed", alert=True,
                     when=aborting),
                Exit(State.completed, CHARGING_FAILED, "charging_failed", alert=True),
            ),
            timeout=(
                Exit(State.failed, "{label} did not finish within {timeout} s",
                     "charging_timeout", alert=True),
            ),
        ),
        Step(State.completed, 9, "Completed"),
        Step(State.incomplete, 9, "Incomplete"),
        Step(State.aborted, 9, "Aborted"),
        Step(State.failed, 9, "Failed"),
    )
}  # fmt: skip


# --- the evaluator --------------------------------------------------------------------


def advance(state: State, obs: Observations, *, aborting: bool = False) -> Transition | None:
    """The next transition of a run in `state`, or None to keep waiting.

    In order: an operator's abort (the step's abort exit; a step without one is already
    heading home and carries on as an aborting run), a failed command, completion, then the
    time budget. The first exit whose guard holds wins.
    """
    if state in FINAL:
        return None
    step = STEPS[state]
    if obs.abort_requested and not aborting:
        if step.abort:
            return _first(step.abort, Seen(step, obs, aborting, None))
        aborting = True
    seen = Seen(step, obs, aborting, _command_failure(step, obs.commands))
    exits = [*(step.failure if seen.failure else ()), *step.done]
    if obs.elapsed_s > obs.timeout_s:
        exits += step.timeout
    return _first(tuple(exits), seen)


def _first(exits: tuple[Exit, ...], seen: Seen) -> Transition | None:
    for exit_ in exits:
        if exit_.when(seen):
            return exit_.take(seen)
    return None


def _command_failure(
    step: Step, outcomes: Mapping[tuple[str, str], CommandOutcome]
) -> tuple[Action, CommandOutcome] | None:
    for action in step.actions:
        outcome = outcomes.get((action.target, action.name))
        if outcome and outcome.final and outcome.status != "succeeded":
            return action, outcome
    return None


def _failed_conditions(outcome: CommandOutcome) -> str:
    try:
        summary = AvailabilityReport.model_validate(outcome.data or {}).summary
    except ValueError:  # no report (e.g. the command failed before checking): its reason says why
        summary = ""
    return summary or outcome.reason or outcome.status
