"""What a run tells operators (its progress message) and the metrics (its step times, outcome)."""

from __future__ import annotations

from datetime import datetime

from protocol.vocabulary import RunProgressPayload
from server.kit import metrics
from server.kit.time import utcnow
from server.runs.machine import FINAL, STEPS, TOTAL_STEPS, State
from server.runs.models import Run


def progress_payload(run: Run, label_override: str | None = None) -> RunProgressPayload:
    """What operators see of a run: readable step, number, status, reason."""
    state = State(run.state)
    step = STEPS[state]
    return RunProgressPayload(
        run_id=run.id,
        state=state.value,
        step=step.number,
        total_steps=TOTAL_STEPS,
        label=label_override or step.label,
        final=state in FINAL,
        outcome=run.outcome,  # type: ignore[arg-type]
        cause=run.cause,
        issues=tuple(run.issues or ()),
        reason=run.reason,
        alert=run.alert,
        mission_id=run.mission_id,
        uav_id=run.uav_id,
        base_id=run.base_id,
        at=utcnow(),
    )


def observe_transition(left: str, entered: datetime | None, run: Run) -> None:
    """The time spent in the step just left; a run that ended counted by outcome and cause."""
    if entered is not None:
        metrics.RUN_STEP.labels(left).observe((utcnow() - entered).total_seconds())
    if run.outcome is not None and State(run.state) in FINAL:
        metrics.RUNS.labels(run.outcome, run.cause or "").inc()
