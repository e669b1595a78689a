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


def charger_idle_reason(plc: PlcState | None, link_up: bool) -> str:
    """Why the charger is not charging, from one PLC reading (for refusals and failures)."""
    if not link_up or plc is None:
        return "PLC link down"
    state = "unknown" if plc.charger_state is None else plc.charger_state.name.lower()
    why = check_start_charging(plc, link_up)
    if not why.allowed:
        return f"charger {state}; {why.reason.removeprefix('start_charging refused: ')}"
    if not plc.charger_enable:
        return f"charger {state}; CHARGER_ENABLE is off"
    if plc.uav_battery_soc_pct is None:
        return f"charger {state}; no battery link to the UAV's pack"
    return f"charger {state} although enabled with the contacts seated"
