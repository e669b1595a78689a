"""The UAV charger: when charging may start."""

from __future__ import annotations

from base_station.devices.axis import Decision
from base_station.plc.codec import PlcState
from base_station.plc.registers import FaultBit


def check_start_charging(plc: PlcState | None, link_up: bool) -> Decision:
    """Charging needs the link, no E-stop, the lift fully down, contacts seated, no charger fault."""
    if not link_up or plc is None:
        return Decision(False, "start_charging refused: PLC link down")
    reasons = []
    if plc.estop_active:
        reasons.append("E-stop active")
    if not plc.lift_down_limit:
        reasons.append(f"lift is {plc.lift_position_pct:.0f} % up, must be fully down")
    if not plc.charger_contact:
        reasons.append("UAV contacts not seated on the pad")
    if plc.fault_bits & FaultBit.CHARGER:
        reasons.append("charger fault")
    if reasons:
        return Decision(False, "start_charging refused: " + "; ".join(reasons))
    return Decision(True)
