"""What became of the safe actions a run issued on its way to a final state (pure).

A failure before take-off ends the run `failed` and closes the base on the way out ("the base is
being closed"). That sentence is written when the `close` is issued, before anyone knows whether
the base will obey: a base daemon that has just restarted, a PLC with a latched fault or a base
that never answers can refuse it. So the engine keeps watching those safe commands after the run
has ended, and `settle` turns their outcome into the truth: "the base is closed", or "the base
could not be closed ..." with an alert, since then the panels may be open over nobody.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

from server.runs.machine import BEING_CLOSED, CommandOutcome

CLOSED = "the base is closed"
LANDING_HERE = "the UAV took the order to land where it is"


@dataclass(frozen=True)
class Settled:
    """The run's reason rewritten to say what happened, a timeline note, and whether to alert."""

    reason: str
    note: str
    cause: str
    alert: bool


def settle(reason: str, outcomes: Mapping[tuple[str, str], CommandOutcome]) -> Settled | None:
    """The verdict once every safe command has ended; None while one is still running.

    A `stop` that fails before a `close` that succeeds changes nothing (the close is what was
    promised); any other safe command not succeeding leaves the base as it was: an alert.
    """
    if not outcomes or not all(o.final for o in outcomes.values()):
        return None
    failed = [
        (name, o) for (_, name), o in outcomes.items() if o.status != "succeeded" and name != "stop"
    ]
    if not failed:
        note = (
            CLOSED
            if ("base", "close") in outcomes
            else LANDING_HERE
            if ("uav", "land") in outcomes
            else "the safe actions are done"
        )
        return Settled(reason.replace(BEING_CLOSED, CLOSED), note, "safe_state_reached", False)
    name, outcome = failed[0]
    what = "the base could not be closed" if name == "close" else f"{name} did not succeed"
    note = (
        f"{what} ({outcome.status}: {outcome.reason or 'no reason given'}); "
        "the base is left as it was: a person must look"
    )
    if BEING_CLOSED in reason:
        new_reason = reason.replace(BEING_CLOSED, note)
    else:
        new_reason = f"{reason}; {note}"
    return Settled(new_reason, note, "safe_state_not_reached", True)
