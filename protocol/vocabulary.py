"""The command vocabulary: one frozen model per command an asset answers, and what they report.

A `command` message carries ``{"name", "params"}``; `parse(name, params)` turns that pair into
the typed command (`UnknownCommand` for a name outside the vocabulary, pydantic's
`ValidationError` for params that do not fit). The server validates with it when a command is
created, the daemons' dispatcher before a handler runs, so both ends agree on every field.

Also here: the availability report both daemons answer `check_availability` with, the payload
of a run's progress as operators see it, and the one set of final command statuses.
"""

from __future__ import annotations

import uuid
from collections.abc import Mapping
from datetime import datetime
from typing import Annotated, Any, ClassVar, Literal

from pydantic import ConfigDict, Field, ValidationError, model_validator

from protocol.base import Frozen

CommandStatus = Literal[
    "queued", "sent", "in_progress", "succeeded", "rejected", "failed", "canceled", "timed_out"
]
# the statuses a command never leaves: defined here once, for the daemons and the server alike
FINAL_STATUSES: frozenset[str] = frozenset(
    {"succeeded", "rejected", "failed", "canceled", "timed_out"}
)

# MAV_FRAMEs a mission item may use on the wire (the _INT variants 5, 6, 11 included)
ITEM_FRAMES = (0, 2, 3, 5, 6, 10, 11)
Param = Annotated[float, Field(allow_inf_nan=False)] | None


UAV, LANDING_BASE = "uav", "landing_base"  # the asset kinds, as assets' `kind` names them
BOTH = frozenset({UAV, LANDING_BASE})


class CommandParams(Frozen):
    """Base of every command model: `name` is the command's name on the wire, `kinds` the asset
    kinds that answer it (the server refuses it for any other)."""

    name: ClassVar[str]
    kinds: ClassVar[frozenset[str]]


# --- both assets ----------------------------------------------------------------------


class CheckAvailability(CommandParams):
    """Can this asset take part in a run now? The base is told the UAV's mass to weigh it.

    `mass_g` / `mass_window_g` come from the UAV's asset attributes; a UAV ignores them.
    """

    name: ClassVar[str] = "check_availability"
    kinds: ClassVar[frozenset[str]] = BOTH
    mass_g: Annotated[float, Field(ge=0, allow_inf_nan=False)] | None = None
    mass_window_g: Annotated[float, Field(ge=0, allow_inf_nan=False)] | None = None


# --- UAV ------------------------------------------------------------------------------


class MissionItem(Frozen):
    """One mission item on the wire: MAVLink MISSION_ITEM_INT fields, lat/lon in degrees.

    A null param is MAVLink's NaN ("leave unchanged"). Index i of a mission is seq i + 1.
    """

    model_config = ConfigDict(frozen=True, extra="forbid", allow_inf_nan=False)
    command: Annotated[int, Field(gt=0, le=65535, strict=True)]
    frame: Literal[0, 2, 3, 5, 6, 10, 11] = 3
    params: tuple[Param, Param, Param, Param] = (0.0, 0.0, 0.0, 0.0)
    lat: Annotated[float, Field(ge=-90, le=90)] = 0.0
    lon: Annotated[float, Field(ge=-180, le=180)] = 0.0
    alt: Annotated[float, Field(ge=-1_000, le=10_000)] = 0.0
    autocontinue: bool = True


class UploadMission(CommandParams):
    """Upload these items to the autopilot, read them back and compare."""

    name: ClassVar[str] = "upload_mission"
    kinds: ClassVar[frozenset[str]] = frozenset({UAV})
    mission_id: uuid.UUID | None = None
    items: Annotated[tuple[MissionItem, ...], Field(min_length=1, max_length=1000)]
    # the geofence (MAV_CMD_NAV_FENCE_* items, uploaded as MAV_MISSION_TYPE_FENCE) and the rally
    # points (MAV_CMD_NAV_RALLY_POINT, MAV_MISSION_TYPE_RALLY): with `fence` given (even empty,
    # which clears the autopilot's) both are uploaded and read back, and the fence is enabled
    # with RTL as its action when it has items; null leaves the autopilot's fence as it is
    fence: Annotated[tuple[MissionItem, ...], Field(max_length=1000)] | None = None
    rally: Annotated[tuple[MissionItem, ...], Field(max_length=100)] = ()
    fence_alt_max_m: Annotated[float, Field(gt=0, le=10_000)] | None = None


class StartMission(CommandParams):
    """Arm and start the uploaded mission (AUTO)."""

    name: ClassVar[str] = "start_mission"
    kinds: ClassVar[frozenset[str]] = frozenset({UAV})


class ReturnToBase(CommandParams):
    """RTL: back to the base, precision landing on the pad."""

    name: ClassVar[str] = "return_to_base"
    kinds: ClassVar[frozenset[str]] = frozenset({UAV})


class Pause(CommandParams):
    """Hold where it is (BRAKE)."""

    name: ClassVar[str] = "pause"
    kinds: ClassVar[frozenset[str]] = frozenset({UAV})


class Resume(CommandParams):
    """Resume the mission (AUTO)."""

    name: ClassVar[str] = "resume"
    kinds: ClassVar[frozenset[str]] = frozenset({UAV})


class Land(CommandParams):
    """Land where it is."""

    name: ClassVar[str] = "land"
    kinds: ClassVar[frozenset[str]] = frozenset({UAV})


class Abort(CommandParams):
    """Return to the base when flying, disarm on the ground."""

    name: ClassVar[str] = "abort"
    kinds: ClassVar[frozenset[str]] = frozenset({UAV})


class PreclandFault(CommandParams):
    """Inject a fault into one precision-landing source (test and bench use).

    `source` is one of the agent's sources or "marker" (pattern and ArUco); the agent checks it
    and the fault's ranges against its own configuration.
    """

    name: ClassVar[str] = "precland_fault"
    kinds: ClassVar[frozenset[str]] = frozenset({UAV})
    source: Annotated[str, Field(min_length=1, max_length=50)]
    r_drop: float | None = None
    p_keep: float | None = None
    p_drop: float | None = None
    below_m: float | None = None
    above_m: float | None = None


# --- landing base ---------------------------------------------------------------------


class Open(CommandParams):
    """Open the base: side panels, then lift up."""

    name: ClassVar[str] = "open"
    kinds: ClassVar[frozenset[str]] = frozenset({LANDING_BASE})


class Close(CommandParams):
    """Close the base: lift down, then side panels."""

    name: ClassVar[str] = "close"
    kinds: ClassVar[frozenset[str]] = frozenset({LANDING_BASE})


class OpenPanels(CommandParams):
    """Open the side panels only."""

    name: ClassVar[str] = "open_panels"
    kinds: ClassVar[frozenset[str]] = frozenset({LANDING_BASE})


class ClosePanels(CommandParams):
    """Close the side panels only."""

    name: ClassVar[str] = "close_panels"
    kinds: ClassVar[frozenset[str]] = frozenset({LANDING_BASE})


class LiftUp(CommandParams):
    """Raise the lift only."""

    name: ClassVar[str] = "lift_up"
    kinds: ClassVar[frozenset[str]] = frozenset({LANDING_BASE})


class LiftDown(CommandParams):
    """Lower the lift only."""

    name: ClassVar[str] = "lift_down"
    kinds: ClassVar[frozenset[str]] = frozenset({LANDING_BASE})


class Stop(CommandParams):
    """Stop every motor, in any state."""

    name: ClassVar[str] = "stop"
    kinds: ClassVar[frozenset[str]] = frozenset({LANDING_BASE})


class ResetFaults(CommandParams):
    """Clear latched faults (not an active E-stop)."""

    name: ClassVar[str] = "reset_faults"
    kinds: ClassVar[frozenset[str]] = frozenset({LANDING_BASE})


class StartCharging(CommandParams):
    """Start charging the UAV; `current_limit_ma` defaults to the base's configuration."""

    name: ClassVar[str] = "start_charging"
    kinds: ClassVar[frozenset[str]] = frozenset({LANDING_BASE})
    current_limit_ma: Annotated[int, Field(ge=0, le=65535, strict=True)] | None = None


class StopCharging(CommandParams):
    """Stop charging."""

    name: ClassVar[str] = "stop_charging"
    kinds: ClassVar[frozenset[str]] = frozenset({LANDING_BASE})


AssetCommand = (
    CheckAvailability
    | UploadMission
    | StartMission
    | ReturnToBase
    | Pause
    | Resume
    | Land
    | Abort
    | PreclandFault
    | Open
    | Close
    | OpenPanels
    | ClosePanels
    | LiftUp
    | LiftDown
    | Stop
    | ResetFaults
    | StartCharging
    | StopCharging
)
COMMANDS: Mapping[str, type[CommandParams]] = {
    cls.name: cls
    for cls in (
        CheckAvailability,
        UploadMission,
        StartMission,
        ReturnToBase,
        Pause,
        Resume,
        Land,
        Abort,
        PreclandFault,
        Open,
        Close,
        OpenPanels,
        ClosePanels,
        LiftUp,
        LiftDown,
        Stop,
        ResetFaults,
        StartCharging,
        StopCharging,
    )
}


class UnknownCommand(ValueError):
    """A command name outside the vocabulary."""

    def __init__(self, name: str) -> None:
        super().__init__(f"unknown command {name!r}")
        self.command = name


def parse(name: str, params: Mapping[str, Any] | None = None) -> CommandParams:
    """The typed command of a wire `(name, params)` pair.

    Raises `UnknownCommand` for a name outside the vocabulary and pydantic's
    `ValidationError` for params that do not fit its model.
    """
    model = COMMANDS.get(name)
    if model is None:
        raise UnknownCommand(name)
    return model.model_validate(dict(params or {}))


def wrong_kind(command: CommandParams, kind: str) -> str | None:
    """Why an asset of `kind` does not take `command`; None when it does."""
    if kind in command.kinds:
        return None
    return f"{command.name} is a command for a {' or '.join(sorted(command.kinds))}, not a {kind}"


def params_of(command: CommandParams) -> dict[str, Any]:
    """The JSON params of a typed command, as sent on the wire (unset defaults left out)."""
    return command.model_dump(mode="json", exclude_unset=True)


def describe(err: ValidationError) -> str:
    """One line naming each field at fault, e.g. ``items.0.lat: Input should be ...``."""
    parts = []
    for e in err.errors():
        where = ".".join(str(p) for p in e["loc"]) or "params"
        parts.append(f"{where}: {e['msg']}")
    return "; ".join(parts)


# --- reports --------------------------------------------------------------------------

Measure = bool | int | float | str | None


class AvailabilityCondition(Frozen):
    """One go/no-go condition: whether it holds, the measured value, the limit, a sentence."""

    name: Annotated[str, Field(min_length=1, max_length=100)]
    ok: bool
    value: Measure = None
    limit: Measure = None
    message: str = ""


class AvailabilityReport(Frozen):
    """The `data` of a `check_availability` result, from either daemon.

    `conditions` lists every condition checked; `failed` repeats the unmet ones (none is
    skipped when another fails) and `available` is true exactly when there are none.
    """

    available: bool
    conditions: tuple[AvailabilityCondition, ...] = ()
    failed: tuple[AvailabilityCondition, ...] = ()

    @model_validator(mode="after")
    def _consistent(self) -> AvailabilityReport:
        if self.available == bool(self.failed) or any(c.ok for c in self.failed):
            raise ValueError("available must be true exactly when no condition failed")
        return self

    @classmethod
    def of(cls, conditions: list[AvailabilityCondition]) -> AvailabilityReport:
        """The report of these conditions."""
        failed = tuple(c for c in conditions if not c.ok)
        return cls(available=not failed, conditions=tuple(conditions), failed=failed)

    @property
    def summary(self) -> str:
        """The failed conditions' messages in one line ("" when available)."""
        return "; ".join(c.message or c.name for c in self.failed)


RunState = Literal[
    "pending",
    "checking",
    "opening",
    "uploading",
    "flying",
    "landing",
    "confirming",
    "closing",
    "charging",
    "completed",
    "incomplete",
    "aborted",
    "failed",
]
RunOutcomeName = Literal["completed", "completed_with_issues", "incomplete", "aborted", "failed"]


class RunProgressPayload(Frozen):
    """Server -> operator: where an autonomous run stands, readable and numbered."""

    run_id: uuid.UUID
    state: RunState
    step: Annotated[int, Field(ge=0)]
    total_steps: Annotated[int, Field(ge=0)]
    label: str
    final: bool
    outcome: RunOutcomeName | None = None
    cause: str | None = None
    issues: tuple[str, ...] = ()
    reason: str = ""
    alert: bool = False
    mission_id: uuid.UUID
    uav_id: uuid.UUID
    base_id: uuid.UUID
    at: datetime
