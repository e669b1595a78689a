"""`check_availability`: every go/no-go condition with its measured value and its limit."""

from __future__ import annotations

from base_station.config import StationConfig
from base_station.devices.weather import Condition, weather_conditions
from base_station.plc import fault_names
from base_station.snapshot import Snapshot
from protocol.vocabulary import AvailabilityCondition, AvailabilityReport


def availability(snap: Snapshot, config: StationConfig) -> AvailabilityReport:
    """The `check_availability` answer: every condition, the failed ones repeated."""
    return AvailabilityReport.of([_wire(c) for c in conditions(snap, config)])


def _wire(c: Condition) -> AvailabilityCondition:
    return AvailabilityCondition(
        name=c.name, ok=c.ok, value=c.measured, limit=c.limit, message=c.message
    )


def conditions(snap: Snapshot, config: StationConfig) -> list[Condition]:
    """All conditions (weather, base health, UAV present); none is skipped when another fails."""
    if not snap.link_up or snap.plc is None:
        return [
            Condition("plc_link", False, "down", "up", f"PLC link down ({snap.link_error})"),
            Condition("weather", False, None, None, "weather unknown: PLC link down"),
            Condition("uav_present", False, None, None, "UAV presence unknown: PLC link down"),
        ]
    plc, w, u = snap.plc, config.weather, config.uav
    out = [Condition("plc_link", True, "up", "up", "PLC link up")]
    out += weather_conditions(
        plc,
        w.max_wind_mps,
        w.max_gust_mps,
        w.max_rain_mm_h,
        w.min_temperature_c,
        w.max_temperature_c,
    )
    out.append(
        Condition(
            "estop",
            not plc.estop_active,
            plc.estop_active,
            False,
            "E-stop active" if plc.estop_active else "E-stop released",
        )
    )
    names = list(fault_names(plc.fault_bits))
    out.append(
        Condition(
            "faults",
            not names,
            ", ".join(names) or "none",
            "none",
            f"faults: {', '.join(names)}" if names else "no faults",
        )
    )
    panels_closed = plc.panels_closed_limit and not plc.panels_moving
    out.append(
        Condition(
            "panels_closed",
            panels_closed,
            plc.panel_position_pct,
            0.0,
            f"panels {plc.panel_position_pct:.0f} % open (must be closed)"
            if not panels_closed
            else "panels closed",
        )
    )
    lift_down = plc.lift_down_limit and not plc.lift_moving
    out.append(
        Condition(
            "lift_down",
            lift_down,
            plc.lift_position_pct,
            0.0,
            f"lift {plc.lift_position_pct:.0f} % up (must be down)"
            if not lift_down
            else "lift down",
        )
    )
    mass = plc.scale_mass_g - u.scale_tare_g
    present = u.min_mass_g <= mass <= u.max_mass_g
    window = f"{u.min_mass_g:.0f}..{u.max_mass_g:.0f} g"
    out.append(
        Condition(
            "uav_present",
            present,
            mass,
            window,
            f"scale {mass:.0f} g {'within' if present else 'outside'} UAV window {window}",
        )
    )
    return out
