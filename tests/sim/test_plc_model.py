"""Unit tests of the pure PLC model: travel, interlocks, stall, E-stop, watchdog, charger."""

from __future__ import annotations

from sim.plc.model import (
    CHARGER_ENABLE,
    FAULT_ESTOP,
    FAULT_LIFT_STALL,
    FAULT_PANEL_STALL,
    FAULT_RESET,
    FAULT_WATCHDOG,
    FAULT_WEATHER,
    LIFT_DOWN,
    LIFT_UP,
    MOTION_STOP,
    PANELS_CLOSE,
    PANELS_OPEN,
    LandingBase,
)
from sim.power import PowerSource, pick_source, solar_output_w
from sim.weather import Weather


def make() -> LandingBase:
    return LandingBase(Weather(seed=1))


def run(base: LandingBase, seconds: float, dt: float = 0.1) -> None:
    for _ in range(round(seconds / dt)):
        base.step(dt)


def cmd(base: LandingBase, coil: int) -> None:
    base.write_coils(coil, [True])


def test_panels_travel_in_12_s_with_limits_and_position() -> None:
    b = make()
    assert b.discrete_inputs()[1] and not b.discrete_inputs()[0]
    cmd(b, PANELS_OPEN)
    assert b.coils()[PANELS_OPEN] is False  # cleared by the PLC
    run(b, 6.0)
    ir = b.input_registers()
    assert 480 <= ir[16] <= 520 and b.discrete_inputs()[4]
    assert b.panels.current_ma > 0
    run(b, 6.2)
    di = b.discrete_inputs()
    assert di[0] and not di[1] and not di[4] and b.input_registers()[16] == 1000


def test_lift_up_refused_until_panels_fully_open() -> None:
    b = make()
    cmd(b, LIFT_UP)
    assert b.discrete_inputs()[10] and not b.lift.moving
    assert b.command_log[-1].reason == "panels not fully open"
    cmd(b, PANELS_OPEN)
    assert not b.discrete_inputs()[10]  # cleared by the accepted command
    run(b, 13)
    cmd(b, LIFT_UP)
    run(b, 8.5)
    assert b.can_vehicle_leave()


def test_panels_close_refused_unless_lift_down() -> None:
    b = make()
    cmd(b, PANELS_OPEN)
    run(b, 13)
    cmd(b, LIFT_UP)
    run(b, 1)
    cmd(b, PANELS_CLOSE)
    assert b.discrete_inputs()[10] and b.panels.at_high
    cmd(b, LIFT_DOWN)
    run(b, 9)
    cmd(b, PANELS_CLOSE)
    run(b, 13)
    assert b.panels.at_low and b.lift.at_low and not b.discrete_inputs()[10]


def test_jammed_motor_stops_after_travel_plus_50_percent_and_latches() -> None:
    b = make()
    b.inject_stall("panels")
    cmd(b, PANELS_OPEN)
    run(b, 17.5)
    assert b.panels.moving and b.panels.current_ma > 2500
    run(b, 1.0)
    assert not b.panels.moving and b.fault_bits() & FAULT_PANEL_STALL
    cmd(b, PANELS_OPEN)
    assert b.discrete_inputs()[10] and not b.panels.moving
    b.inject_stall("panels", on=False)
    cmd(b, FAULT_RESET)
    assert b.fault_bits() == 0
    cmd(b, PANELS_OPEN)
    assert b.panels.moving


def test_immediate_stall_injection_latches_lift_fault() -> None:
    b = make()
    b.inject_stall("lift", immediate=True)
    assert b.fault_bits() & FAULT_LIFT_STALL


def test_estop_stops_everything_and_survives_reset_while_active() -> None:
    b = make()
    cmd(b, PANELS_OPEN)
    run(b, 2)
    b.set_estop(True)
    assert not b.panels.moving and b.discrete_inputs()[6]
    cmd(b, PANELS_OPEN)
    assert not b.panels.moving and b.discrete_inputs()[10]
    cmd(b, FAULT_RESET)
    assert b.fault_bits() & FAULT_ESTOP
    b.set_estop(False)
    assert b.fault_bits() & FAULT_ESTOP  # latched until reset
    cmd(b, FAULT_RESET)
    assert b.fault_bits() == 0


def test_motion_stop_always_accepted() -> None:
    b = make()
    cmd(b, PANELS_OPEN)
    run(b, 1)
    cmd(b, MOTION_STOP)
    assert not b.panels.moving and b.command_log[-1].accepted


def test_watchdog_arms_on_first_write_and_expires_after_2_s_unchanged() -> None:
    b = make()
    b.tick_wall(100.0)
    b.tick_wall(110.0)
    assert not b.watchdog_armed and b.fault_bits() == 0  # never armed: no fault
    b.write_holding(0, [1], 110.0)
    cmd(b, PANELS_OPEN)
    b.write_holding(0, [1], 111.5)  # same value does not feed it
    b.tick_wall(111.9)
    assert b.panels.moving
    b.tick_wall(112.1)
    assert not b.panels.moving and b.fault_bits() & FAULT_WATCHDOG


def test_watchdog_latch_outlives_a_new_master_until_fault_reset_as_the_spec_says() -> None:
    """Spec: unchanged 2 s -> all motion stops and fault 16 LATCHES; no motion while a fault is
    latched; FAULT_RESET clears latched faults. A master coming back does not clear it by itself,
    and a reset while the watchdog is still starved latches it again."""
    b = make()
    b.write_holding(0, [7], 10.0)
    cmd(b, PANELS_OPEN)
    run(b, 5)
    b.tick_wall(12.1)  # the master is gone (killed mid-open)
    assert not b.panels.moving and b.fault_bits() & FAULT_WATCHDOG
    stopped_at = b.panels.position
    cmd(b, FAULT_RESET)  # reset while nobody feeds the watchdog...
    b.tick_wall(12.2)
    assert b.fault_bits() & FAULT_WATCHDOG  # ...latches again at once
    for i in range(1, 9):  # a new master feeds it for 4 s
        b.write_holding(0, [i], 12.2 + i * 0.5)
        b.tick_wall(12.3 + i * 0.5)
    assert b.fault_bits() & FAULT_WATCHDOG  # still latched
    cmd(b, PANELS_CLOSE)
    assert not b.command_log[-1].accepted and "faults latched (16)" in b.command_log[-1].reason
    cmd(b, FAULT_RESET)
    b.write_holding(0, [100], 17.0)
    b.tick_wall(17.1)
    assert b.fault_bits() == 0 and not b.panels.moving and b.panels.position == stopped_at
    cmd(b, PANELS_CLOSE)
    assert b.command_log[-1].accepted and b.panels.moving


def test_watchdog_fed_by_changing_values() -> None:
    b = make()
    for i in range(40):
        b.write_holding(0, [i], 100.0 + i * 0.5)
        b.tick_wall(100.0 + i * 0.5 + 0.4)
    assert b.fault_bits() == 0


def test_heartbeat_counts_100_ms_of_wall_time_and_wraps() -> None:
    b = make()
    b.tick_wall(50.0)
    b.tick_wall(50.35)
    assert b.heartbeat == 3
    b.tick_wall(50.0 + 6553.6)
    assert b.heartbeat == 0


def test_scale_is_tare_plus_load_plus_noise_as_uint32() -> None:
    b = make()
    b.set_pad_load(1500.0, True)
    b.step(0.1)
    ir = b.input_registers()
    mass = (ir[0] << 16) | ir[1]
    assert abs(mass - 1515) < 15


def test_charger_cc_then_cv_to_complete_honours_limit() -> None:
    b = make()
    b.set_pad_load(1500, True)
    b.set_uav_battery(0.5)
    b.write_holding(1, [3000], 0.0)
    cmd(b, CHARGER_ENABLE)
    currents, states = [], []
    for _ in range(6000):
        b.step(1.0)
        ir = b.input_registers()
        currents.append(ir[9])
        states.append(ir[8])
        if ir[8] == 2:
            break
    assert states[0] == 1 and currents[0] == 3000  # CC at the limit
    assert states[-1] == 2 and b.input_registers()[11] >= 990
    tail = [c for c in currents if 0 < c < 3000]
    assert tail and tail == sorted(tail, reverse=True)  # CV: current tapers


def test_charger_needs_lift_down_and_contacts() -> None:
    b = make()
    b.set_uav_battery(0.5)
    b.set_pad_load(1500, False)
    cmd(b, CHARGER_ENABLE)
    b.step(1.0)
    assert b.input_registers()[8] == 0 and b.input_registers()[11] == 65535


def test_weather_sensor_fault_zeroes_weather_and_sets_bit_8_without_blocking_motion() -> None:
    b = make()
    b.weather.sensor_fault = True
    assert b.input_registers()[2:8] == [0] * 6 and b.fault_bits() & FAULT_WEATHER
    cmd(b, PANELS_OPEN)
    assert b.panels.moving


def test_negative_temperature_encoded_as_int16() -> None:
    b = make()
    b.weather.force(temperature_c=-8.5)
    assert b.input_registers()[6] == (-85) & 0xFFFF


def test_power_rule() -> None:
    assert pick_source(200, 50, True) is PowerSource.SOLAR
    assert pick_source(10, 50, True) is PowerSource.GRID
    assert pick_source(10, 50, False) is PowerSource.BATTERY
    assert solar_output_w(3.0, 300) == 0.0 and solar_output_w(12.0, 300) == 300.0


def test_cpu_halt_freezes_heartbeat_and_ignores_commands() -> None:
    b = make()
    b.tick_wall(10.0)
    cmd(b, PANELS_OPEN)
    b.set_cpu_halt(True)
    assert not b.panels.moving
    b.tick_wall(11.0)
    assert b.heartbeat == 0
    cmd(b, PANELS_OPEN)
    assert not b.panels.moving and len(b.command_log) == 1
    b.set_cpu_halt(False)
    b.tick_wall(11.5)
    assert b.heartbeat == 15


# --- property: whatever a master writes, the lift is never off its down limit unless the
# panels are fully open, and nothing moves under E-stop -------------------------------------

from hypothesis import given, settings  # noqa: E402
from hypothesis import strategies as st  # noqa: E402

actions = st.one_of(
    st.tuples(st.just("coil"), st.integers(0, 6)),
    st.tuples(st.just("step"), st.floats(0.05, 6.0)),
    st.tuples(st.just("estop"), st.booleans()),
    st.tuples(st.just("jam"), st.sampled_from(["panels", "lift"])),
)


@settings(max_examples=150, deadline=None)
@given(st.lists(actions, max_size=40))
def test_interlocks_hold_for_any_command_sequence(seq: list[tuple[str, object]]) -> None:
    b = make()
    for kind, arg in seq:
        if kind == "coil":
            b.write_coils(int(arg), [True])  # type: ignore[call-overload]
        elif kind == "step":
            for _ in range(int(float(arg) / 0.5) + 1):  # type: ignore[arg-type]
                b.step(0.5)
        elif kind == "estop":
            b.set_estop(bool(arg))
        else:
            b.inject_stall(str(arg))
        assert b.lift.position == 0.0 or b.panels.at_high
        if b.estop_active:
            assert not b.panels.moving and not b.lift.moving
        assert all(not c for i, c in enumerate(b.coils()) if i != CHARGER_ENABLE)
