"""Unit tests of the pure device logic, event derivation, telemetry and configuration."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import pytest
from pydantic import ValidationError

from base_station.base_telemetry import build_telemetry
from base_station.config import StationConfig, load_config
from base_station.devices.axis import MotionState, MotionTracker, Outcome, motion_state
from base_station.devices.charger import check_start_charging
from base_station.devices.lift import LIFT, check_lift_down, check_lift_up
from base_station.devices.panels import PANELS, check_close_panels, check_open_panels
from base_station.devices.scale import LandingDetector
from base_station.devices.weather import weather_conditions
from base_station.events import EventKind, diff_events
from base_station.plc import ChargerState, FaultBit, PlcState, PowerSource, RawImage, decode
from base_station.snapshot import Snapshot
from protocol.telemetry_payloads import Actuator, LandingBaseTelemetry, Rtk


def closed_base(**changes: object) -> PlcState:
    """A healthy closed base with the lift down."""
    inputs = [0] * 20
    inputs[11] = 65535
    discrete = [False, True, False, True] + [False] * 7
    s = decode(RawImage((False,) * 7, tuple(discrete), tuple(inputs), (0, 5000)))
    return dataclasses.replace(s, grid_present=True, **changes)


def snap(plc: PlcState | None, seq: int = 1, link_up: bool = True, **kw: object) -> Snapshot:
    return Snapshot(seq, 0.0, 0.0, link_up, "" if link_up else "boom", plc, **kw)


# --- interlocks -------------------------------------------------------------------------


def test_lift_up_needs_panels_fully_open_and_says_why() -> None:
    s = closed_base(panels_closed_limit=False, panel_position_pct=40.0)
    d = check_lift_up(s, True)
    assert not d.allowed
    assert d.reason == "lift up refused: panels are 40 % open, must be fully open"
    moving = dataclasses.replace(s, panels_moving=True)
    assert "40 % open, moving" in check_lift_up(moving, True).reason
    ok = closed_base(panels_closed_limit=False, panels_open_limit=True, panel_position_pct=100.0)
    assert check_lift_up(ok, True).allowed


def test_panels_close_needs_lift_fully_down() -> None:
    s = closed_base(
        panels_open_limit=True,
        panels_closed_limit=False,
        lift_down_limit=False,
        lift_position_pct=35.0,
    )
    d = check_close_panels(s, True)
    assert not d.allowed and "lift is 35 % up, must be fully down" in d.reason


def test_link_down_estop_and_faults_block_every_motion_and_all_reasons_are_given() -> None:
    for check in (check_open_panels, check_close_panels, check_lift_up, check_lift_down):
        assert "PLC link down" in check(closed_base(), False).reason
        assert "PLC link down" in check(None, True).reason
    s = closed_base(estop_active=True, fault_bits=FaultBit.ESTOP | FaultBit.LIFT_STALL)
    d = check_open_panels(s, True)
    assert "E-stop active" in d.reason and "faults latched: LIFT_STALL, ESTOP" in d.reason


def test_live_status_faults_do_not_block_motion() -> None:
    s = closed_base(fault_bits=FaultBit.WEATHER_SENSOR | FaultBit.CHARGER)
    assert check_open_panels(s, True).allowed


def test_already_there_and_already_moving() -> None:
    assert check_close_panels(closed_base(), True).already_there
    assert check_lift_down(closed_base(), True).already_there
    moving = closed_base(panels_moving=True, panels_closed_limit=False, panel_position_pct=12.0)
    d = check_open_panels(moving, True)
    assert not d.allowed and "panels already moving (at 12 %)" in d.reason


def test_charging_needs_lift_down_and_contacts() -> None:
    d = check_start_charging(closed_base(lift_down_limit=False, lift_position_pct=50.0), True)
    assert "lift is 50 % up" in d.reason and "contacts not seated" in d.reason
    assert check_start_charging(closed_base(charger_contact=True), True).allowed
    assert not check_start_charging(closed_base(charger_contact=True), False).allowed


# --- motion tracking ----------------------------------------------------------------------


def opening(pos: float, **kw: object) -> PlcState:
    return closed_base(panels_closed_limit=False, panels_moving=True, panel_position_pct=pos, **kw)


def test_tracker_succeeds_at_the_limit() -> None:
    t = MotionTracker(PANELS, +1, started_at=0.0, timeout_s=20.0)
    assert t.update(opening(50.0), True, 5.0, True)[0] is Outcome.RUNNING
    done = closed_base(panels_closed_limit=False, panels_open_limit=True, panel_position_pct=100.0)
    assert t.update(done, True, 12.0, True) == (Outcome.SUCCEEDED, "panels open")


def test_tracker_failures_name_their_cause() -> None:
    t = MotionTracker(PANELS, +1, 0.0, 20.0)
    assert "PLC link lost" in t.update(None, False, 1.0, True)[1]
    assert "E-stop" in t.update(opening(10.0, estop_active=True), True, 1.0, True)[1]
    stall = closed_base(
        panels_closed_limit=False, fault_bits=FaultBit.PANEL_STALL, panel_position_pct=30.0
    )
    assert t.update(stall, True, 1.0, True) == (
        Outcome.FAILED,
        "panels motor stall at 30 %: stopped by the PLC",
    )
    wd = opening(10.0, fault_bits=FaultBit.WATCHDOG)
    assert "WATCHDOG latched" in t.update(wd, True, 1.0, True)[1]
    out, reason = t.update(opening(60.0), True, 21.0, True)
    assert out is Outcome.FAILED and reason.startswith("travel timeout: panels at 60 %")


def test_tracker_ignores_stale_snapshots_and_detects_plc_refusal() -> None:
    t = MotionTracker(LIFT, +1, 0.0, 20.0)
    still = closed_base()
    assert t.update(still, True, 0.1, fresh=False)[0] is Outcome.RUNNING
    refused = closed_base(interlock_refused=True)
    assert t.update(refused, True, 0.1, True) == (
        Outcome.FAILED,
        "lift to up refused by the PLC interlock",
    )


def test_tracker_reports_a_stop_before_the_limit() -> None:
    t = MotionTracker(LIFT, -1, 0.0, 20.0)
    lowering = closed_base(lift_down_limit=False, lift_moving=True, lift_position_pct=70.0)
    assert t.update(lowering, True, 1.0, True)[0] is Outcome.RUNNING
    halted = closed_base(lift_down_limit=False, lift_position_pct=60.0)
    assert t.update(halted, True, 2.0, True) == (
        Outcome.FAILED,
        "lift stopped at 60 % before reaching the limit",
    )


def test_motion_state_vocabulary() -> None:
    r = PANELS.read(opening(30.0))
    assert motion_state(r, +1) is MotionState.OPENING
    assert motion_state(r, -1) is MotionState.CLOSING
    assert motion_state(r, 0) is MotionState.MOVING
    assert motion_state(PANELS.read(closed_base()), 0) is MotionState.CLOSED
    stalled = PANELS.read(closed_base(fault_bits=FaultBit.PANEL_STALL))
    assert motion_state(stalled, 0) is MotionState.FAULT


# --- scale --------------------------------------------------------------------------------


def test_landing_needs_mass_in_window_stable_for_the_whole_window() -> None:
    d = LandingDetector(1200, 1800, stable_s=3.0, tolerance_g=40, tare_g=15)
    assert d.update(0.0, 15)[0].present is False
    status, new = d.update(1.0, 1515)
    assert status.present and status.mass_g == 1500 and not new
    assert d.update(3.9, 1520)[1] is False
    status, new = d.update(4.0, 1510)
    assert new and status.confirmed and status.stable_for_s == 3.0
    assert d.update(4.5, 1512) == (d.update(4.5, 1512)[0], False)  # stays, no second event


def test_landing_window_restarts_when_the_mass_wobbles_or_leaves() -> None:
    d = LandingDetector(1200, 1800, stable_s=3.0, tolerance_g=40)
    d.update(0.0, 1500)
    d.update(2.0, 1600)  # a wobble of 100 g restarts the window
    assert d.update(4.0, 1600)[0].confirmed is False
    assert d.update(5.0, 1600)[1] is True
    assert d.update(6.0, 2500)[0].confirmed is False  # someone leaned on it
    assert d.update(6.5, 1600)[0].stable_for_s == 0.0


# --- weather ------------------------------------------------------------------------------


def test_weather_conditions_each_against_its_limit() -> None:
    s = closed_base(wind_speed_mps=9.0, wind_gust_mps=10.0, rain_rate_mm_h=0.0, temperature_c=41.0)
    conds = {c.name: c for c in weather_conditions(s, 8.0, 12.0, 0.0, -5.0, 40.0)}
    assert not conds["wind"].ok and conds["gust"].ok and conds["rain"].ok
    assert conds["temperature_min"].ok and not conds["temperature_max"].ok
    rain_only = closed_base(rain_detected=True)
    assert not {c.name: c for c in weather_conditions(rain_only, 8, 12, 0, -5, 40)}["rain"].ok


# --- events and telemetry -----------------------------------------------------------------


def test_events_between_snapshots() -> None:
    a = closed_base(power_source=PowerSource.SOLAR, charger_state=ChargerState.CHARGING)
    b = dataclasses.replace(
        a,
        fault_bits=FaultBit.LIFT_STALL,
        estop_active=True,
        power_source=PowerSource.GRID,
        charger_state=ChargerState.COMPLETE,
        interlock_refused=True,
    )
    kinds = [e.kind for e in diff_events(snap(a), snap(b, 2))]
    assert kinds == [
        EventKind.FAULT,
        EventKind.ESTOP,
        EventKind.PLC_INTERLOCK_REFUSED,
        EventKind.CHARGE_COMPLETE,
        EventKind.POWER_SOURCE_CHANGED,
    ]
    lost = diff_events(snap(b, 2), snap(b, 3, link_up=False))
    assert [e.kind for e in lost] == [EventKind.PLC_LINK_LOST]
    back = diff_events(snap(b, 3, link_up=False), snap(b, 4))
    assert [e.kind for e in back] == [EventKind.PLC_LINK_RESTORED]
    first = diff_events(None, snap(b))  # a restart reports the faults it finds
    assert EventKind.FAULT in [e.kind for e in first]


def test_telemetry_from_a_snapshot_and_before_any_read() -> None:
    s = closed_base(
        fault_bits=FaultBit.WEATHER_SENSOR,
        charger_state=ChargerState.IDLE,
        power_source=PowerSource.BATTERY,
    )
    t = build_telemetry(snap(s, panels=MotionState.CLOSED, lift=MotionState.CLOSED))
    assert isinstance(t, LandingBaseTelemetry) and t.kind == "landing_base"
    assert t.plc_link == "up" and t.panels is not None and t.panels.state == "closed"
    assert t.faults.names == ("weather_sensor_fault",) and t.faults.bits == FaultBit.WEATHER_SENSOR
    assert t.power is not None and t.power.source == "battery"
    assert t.charger is not None and t.charger.state == "idle"
    assert t.charger.uav_battery_pct is None and t.rtk is None
    empty = build_telemetry(snap(None, link_up=False))
    assert empty.plc_link == "down" and empty.panels is None and empty.weather is None
    assert empty.faults.bits == 0 and empty.estop is None
    assert LandingBaseTelemetry.model_validate_json(empty.model_dump_json()) == empty


def test_telemetry_clamps_readings_into_the_wire_ranges_and_carries_rtk() -> None:
    s = closed_base(
        panel_position_pct=100.4,
        lift_position_pct=-0.2,
        humidity_pct=100.7,
        wind_direction_deg=370,
        uav_battery_soc_pct=101.0,
        charge_current_ma=1500,
    )
    rtk = Rtk(state="streaming", corrections_rate=1.0)
    t = build_telemetry(snap(s, panels=MotionState.OPEN, lift=MotionState.STOPPED), rtk)
    assert t.panels == Actuator(state="open", position_pct=100.0)
    assert t.lift == Actuator(state="stopped", position_pct=0.0)
    assert t.weather is not None and t.weather.humidity_pct == 100.0
    assert t.weather.direction_deg == 10
    assert t.charger is not None and t.charger.uav_battery_pct == 100.0
    assert t.charger.current_a == 1.5 and t.rtk == rtk


# --- configuration ------------------------------------------------------------------------


def test_config_from_toml(tmp_path: Path) -> None:
    f = tmp_path / "base.toml"
    f.write_text(
        "[plc]\nport = 5020\npoll_hz = 10\n[uav]\nmin_mass_g = 900\nmax_mass_g = 1100\n"
        '[rtk]\nserial_device = "/dev/ttyACM0"\n'
    )
    cfg = load_config(f)
    assert cfg.plc.port == 5020 and cfg.plc.poll_hz == 10 and cfg.uav.max_mass_g == 1100
    assert cfg.weather.max_wind_mps == 8.0 and cfg.rtk.serial_device == "/dev/ttyACM0"


def test_config_rejects_bad_values() -> None:
    with pytest.raises(ValidationError):
        StationConfig.model_validate({"plc": {"poll_hz": 1}})  # must poll at >= 5 Hz
    with pytest.raises(ValidationError):
        StationConfig.model_validate({"plc": {"watchdog_period_s": 0.8}})
    with pytest.raises(ValidationError):
        StationConfig.model_validate({"uav": {"min_mass_g": 2000, "max_mass_g": 1000}})
    with pytest.raises(ValidationError):
        StationConfig.model_validate({"plc": {"bogus": 1}})
