"""The lift (landing platform): its axis spec and the interlocks the daemon enforces."""

from __future__ import annotations

from base_station.devices.axis import AxisReading, AxisSpec, Decision, motion_blockers, refused
from base_station.plc.codec import PlcState
from base_station.plc.registers import Coil, FaultBit


def read_lift(plc: PlcState) -> AxisReading:
    """The lift's limit switches, moving flag, position and stall bit."""
    return AxisReading(
        at_open=plc.lift_up_limit,
        at_closed=plc.lift_down_limit,
        moving=plc.lift_moving,
        position_pct=plc.lift_position_pct,
        stalled=bool(plc.fault_bits & FaultBit.LIFT_STALL),
    )


LIFT = AxisSpec("lift", "up", "down", Coil.LIFT_UP, Coil.LIFT_DOWN, FaultBit.LIFT_STALL, read_lift)


def check_lift_up(plc: PlcState | None, link_up: bool) -> Decision:
    """May the lift start rising? Only with the panels fully open."""
    reasons = motion_blockers(plc, link_up)
    if plc is not None and link_up and plc.lift_moving:
        reasons.append(f"lift already moving (at {plc.lift_position_pct:.0f} %), stop first")
    if plc is not None and link_up and not (plc.panels_open_limit and not plc.panels_moving):
        moving = ", moving" if plc.panels_moving else ""
        reasons.append(
            f"panels are {plc.panel_position_pct:.0f} % open{moving}, must be fully open"
        )
    if reasons:
        return refused("lift up", reasons)
    assert plc is not None
    if plc.lift_up_limit and not plc.lift_moving:
        return Decision(True, "lift already up", already_there=True)
    return Decision(True)


def check_lift_down(plc: PlcState | None, link_up: bool) -> Decision:
    """May the lift start lowering?"""
    reasons = motion_blockers(plc, link_up)
    if plc is not None and link_up and plc.lift_moving:
        reasons.append(f"lift already moving (at {plc.lift_position_pct:.0f} %), stop first")
    if reasons:
        return refused("lift down", reasons)
    assert plc is not None
    if plc.lift_down_limit and not plc.lift_moving:
        return Decision(True, "lift already down", already_there=True)
    return Decision(True)
