"""The UAV charger: when charging may start, and why it is not charging."""

from __future__ import annotations

from base_station.devices.axis import Decision
from base_station.plc.codec import PlcState
from base_station.plc.registers import FaultBit


def _blockers(plc: PlcState) -> list[str]:
    """What keeps the charger from charging, in the PLC's own interlocks."""
    reasons = []
    if plc.estop_active:
        reasons.append("E-stop active")
    if not plc.lift_down_limit:
        reasons.append(f"lift is {plc.lift_position_pct:.0f} % up, must be fully down")
    if not plc.charger_contact:
        reasons.append("UAV contacts not seated on the pad")
    if plc.fault_bits & FaultBit.CHARGER:
        reasons.append("charger fault")
    return reasons


def check_start_charging(plc: PlcState | None, link_up: bool) -> Decision:
    """Charging needs the link, no E-stop, the lift fully down, contacts seated, no charger fault."""
    if not link_up or plc is None:
        return Decision(False, "start_charging refused: PLC link down")
    if reasons := _blockers(plc):
        return Decision(False, "start_charging refused: " + "; ".join(reasons))
    return Decision(True)


def charger_idle_reason(plc: PlcState | None, link_up: bool) -> str:
    """Why the charger is not charging, from one PLC reading (for refusals and failures)."""
    if not link_up or plc is None:
        return "PLC link down"
    state = "unknown" if plc.charger_state is None else plc.charger_state.name.lower()
    reasons = _blockers(plc)
    if not plc.charger_enable:
        reasons.append("CHARGER_ENABLE is off")
    if plc.uav_battery_soc_pct is None:
        reasons.append("no battery link to the UAV's pack")
    if not reasons:
        return f"charger {state} although enabled with the contacts seated"
    return f"charger {state}; " + "; ".join(reasons)
