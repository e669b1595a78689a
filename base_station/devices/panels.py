"""The side panels: their axis spec and the interlocks the daemon enforces before moving them."""

from __future__ import annotations

from base_station.devices.axis import AxisReading, AxisSpec, Decision, motion_blockers, refused
from base_station.plc.codec import PlcState
from base_station.plc.registers import Coil, FaultBit


def read_panels(plc: PlcState) -> AxisReading:
    """The panels' limit switches, moving flag, position and stall bit."""
    return AxisReading(
        at_open=plc.panels_open_limit,
        at_closed=plc.panels_closed_limit,
        moving=plc.panels_moving,
        position_pct=plc.panel_position_pct,
        stalled=bool(plc.fault_bits & FaultBit.PANEL_STALL),
    )


PANELS = AxisSpec(
    "panels",
    "open",
    "closed",
    Coil.PANELS_OPEN,
    Coil.PANELS_CLOSE,
    FaultBit.PANEL_STALL,
    read_panels,
)


def check_open_panels(plc: PlcState | None, link_up: bool) -> Decision:
    """May the panels start opening?"""
    reasons = motion_blockers(plc, link_up)
    if plc is not None and link_up and plc.panels_moving:
        reasons.append(f"panels already moving (at {plc.panel_position_pct:.0f} %), stop first")
    if reasons:
        return refused("open panels", reasons)
    assert plc is not None
    if plc.panels_open_limit and not plc.panels_moving:
        return Decision(True, "panels already open", already_there=True)
    return Decision(True)


def check_close_panels(plc: PlcState | None, link_up: bool) -> Decision:
    """May the panels start closing? Only with the lift fully down."""
    reasons = motion_blockers(plc, link_up)
    if plc is not None and link_up and plc.panels_moving:
        reasons.append(f"panels already moving (at {plc.panel_position_pct:.0f} %), stop first")
    if plc is not None and link_up and not (plc.lift_down_limit and not plc.lift_moving):
        moving = ", moving" if plc.lift_moving else ""
        reasons.append(f"lift is {plc.lift_position_pct:.0f} % up{moving}, must be fully down")
    if reasons:
        return refused("close panels", reasons)
    assert plc is not None
    if plc.panels_closed_limit and not plc.panels_moving:
        return Decision(True, "panels already closed", already_there=True)
    return Decision(True)
