"""The immutable view of the base the coordinator hands out after every poll."""

from __future__ import annotations

from dataclasses import dataclass

from base_station.devices.axis import MotionState
from base_station.devices.scale import LandingStatus
from base_station.plc.codec import PlcState


@dataclass(frozen=True)
class Snapshot:
    """One poll: link state, the PLC's decoded state (last known when the link is down),
    derived axis states and the landing status."""

    seq: int
    read_started: float  # time.monotonic() when the read began
    ts: float  # unix time
    link_up: bool
    link_error: str
    plc: PlcState | None
    panels: MotionState | None = None
    lift: MotionState | None = None
    landing: LandingStatus | None = None
