"""API shapes of runs and reports."""

from __future__ import annotations

import uuid
from typing import Any

from pydantic import BaseModel, ConfigDict, Field

from server.kit.types import Text, Timestamp
from server.runs.machine import RunState
from server.runs.outcome import RunIssue, RunOutcome
from server.video.schemas import RecordingOut

__all__ = ["RunIssue", "RunOutcome"]  # the API's enums, decided in runs/outcome.py


class RunCreate(BaseModel):
    """Start a run: a mission, the UAV that flies it, the base it leaves from and returns to."""

    model_config = ConfigDict(extra="forbid")
    mission_id: uuid.UUID
    uav_id: uuid.UUID
    base_id: uuid.UUID


class AbortRequest(BaseModel):
    """Why the operator aborts."""

    model_config = ConfigDict(extra="forbid")
    reason: Text = ""


class TransitionOut(BaseModel):
    """One step of a run's timeline."""

    model_config = ConfigDict(from_attributes=True)
    at: Timestamp
    from_state: RunState
    to_state: RunState
    reason: str
    cause: str


class RunOut(BaseModel):
    """A run, its step and (when read alone) its timeline."""

    model_config = ConfigDict(from_attributes=True)
    id: uuid.UUID
    mission_id: uuid.UUID
    uav_id: uuid.UUID
    base_id: uuid.UUID
    schedule_id: uuid.UUID | None
    scheduled_for: Timestamp | None
    state: RunState
    step: int = 0
    total_steps: int = 0
    label: str = ""
    outcome: RunOutcome | None
    cause: str | None
    issues: list[RunIssue] = Field(
        default_factory=list,
        description="degradations that did not stop the job (a `completed_with_issues` run's, or "
        "any run's whose charging was refused): `charging_refused`, `landing_off_contacts`, "
        "`landed_without_precision`",
    )
    reason: str
    alert: bool
    abort_requested: bool
    created_at: Timestamp
    updated_at: Timestamp
    finished_at: Timestamp | None
    timeline: list[TransitionOut] = []


class LandingReport(BaseModel):
    """Where the UAV touched down, as the agent measured it, and whether the base confirmed it."""

    agent_offset_m: float | None = Field(
        description="horizontal distance from the pad's centre at the agent's last measured fix "
        "(precision landing); null when it landed without one"
    )
    agent_offset_north_m: float | None
    agent_offset_east_m: float | None
    agent_fix_height_m: float | None = Field(description="the fix's height above the pad")
    agent_fix_age_s: float | None = Field(description="how old that fix was at touchdown")
    agent_fix_sources: str | None = Field(description='e.g. "pattern+aruco+ir"')
    agent_landing_path: str | None = Field(
        description='which way the landing went: "precision" (the pad in view), '
        '"search-then-precision", "rtk-fallback" (searched in vain, landed on RTK fixed GNSS over '
        'the surveyed pad), "aborted-climb" (searched in vain without RTK fixed: climbed, did not '
        'land), "gnss" (landed without a measurement of the pad); null when not reported'
    )
    landed_at: Timestamp | None = Field(description="when the agent reported the touchdown")
    base_confirmed: bool = Field(description="the base weighed the UAV, stable, in its window")
    base_confirmed_at: Timestamp | None
    base_mass_g: float | None


class BreachOut(BaseModel):
    """A geofence breach the UAV's autopilot reported during the run (it returned on its own)."""

    at: Timestamp  # when the agent saw the autopilot's FENCE_STATUS breach
    breach_type: str = Field(description="BOUNDARY (a polygon or circle), MAXALT or MINALT")
    breach_count: int | None
    mode: str | None = Field(description="the flight mode at the breach (RTL: the fence's action)")
    lat: float | None
    lon: float | None
    alt_rel_m: float | None


class RunReport(BaseModel):
    """The flight history of one run."""

    run: RunOut
    flight_time_s: float | None = Field(
        description="take-off to touchdown by the UAV's own `took_off` and `landed` events (to "
        "now while it flies); null before take-off"
    )
    battery_used_pct: float | None
    landing_error_m: float | None = Field(
        description="the agent's measured touchdown offset (landing.agent_offset_m)"
    )
    landing: LandingReport | None = Field(
        description="what the agent and the base reported of the touchdown; null before it"
    )
    track: list[dict[str, Any]]
    airspace_breaches: list[BreachOut] = Field(
        default_factory=list, description="geofence breaches during the flight, oldest first"
    )
    battery_margin_at_touchdown_pct: float | None = Field(
        default=None,
        description="battery at touchdown less the UAV's reserve (null before the landing)",
    )
    recordings: list[RecordingOut] = Field(
        default_factory=list,
        description="the UAV's recorded video segments overlapping the flight (take-off to "
        "landing, or to now while it flies), oldest first; empty before take-off or when "
        "recording is off (GET .../video/recordings)",
    )


class AssetSummary(BaseModel):
    """Per-asset figures of the fleet report."""

    asset_id: uuid.UUID
    runs: int
    completed: int = Field(description="runs of the asset that ended `completed` (clean)")
    flight_time_s: float


class FleetReport(BaseModel):
    """Runs in a window: counts by outcome, success rate, the rest by outcome and cause, mean
    flight time, per asset."""

    start: Timestamp
    end: Timestamp
    runs: int
    completed: int = Field(description="runs that ended `completed`: the job done, no issue")
    completed_with_issues: int = Field(
        description="runs that did the job with a degradation (charging refused, off the contacts)"
    )
    incomplete: int = Field(description="runs that came back before their mission's last item")
    aborted: int
    failed: int
    in_progress: int
    success_rate: float | None = Field(
        description="`completed` runs over finished runs (null with none finished): only a clean "
        "completion counts; `completed_with_issues` and `incomplete` do not"
    )
    by_outcome: dict[RunOutcome, dict[str, int]] = Field(
        description="finished runs other than `completed`, by outcome then cause (an issue for "
        '`completed_with_issues`), e.g. `{"incomplete": {"battery_reserve": 1}}`'
    )
    failures_by_cause: dict[str, int] = Field(
        description="every finished run that is not `completed`, by cause (summed over outcomes)"
    )
    mean_flight_time_s: float | None = Field(
        description="mean take-off to touchdown of the finished runs that flew, by the UAV's own "
        "`took_off` and `landed` events"
    )
    per_asset: list[AssetSummary]
