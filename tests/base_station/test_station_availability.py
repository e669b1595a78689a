"""Availability (every failed condition listed), landing confirmation, charging to completion."""

from __future__ import annotations

import asyncio

import pytest
from bs_helpers import SPEED, Rig, rig_at, run, start_daemon, station_config, stop_daemon

from base_station.events import EventKind
from base_station.plc import FaultBit
from base_station.station import Status
from sim.world import World, WorldConfig
from tests.polling import eventually


async def test_available_when_everything_is_fine(rig: Rig) -> None:
    await rig.inject("/pad", {"mass_g": 1500, "contacts_seated": True})
    await eventually(lambda: rig.station.telemetry().uav_present is True, what="UAV on the scale")
    result = await run(rig.station, "check_availability")
    assert result.status is Status.SUCCEEDED and result.data["available"], result.reason
    assert {c["name"] for c in result.data["conditions"]} >= {
        "plc_link",
        "wind",
        "gust",
        "rain",
        "temperature_min",
        "temperature_max",
        "estop",
        "faults",
        "panels_closed",
        "lift_down",
        "uav_present",
    }


async def test_every_failed_condition_is_listed_with_measured_value_and_limit(rig: Rig) -> None:
    await rig.inject(
        "/weather/force",
        {"wind_mps": 11.0, "gust_mps": 16.0, "rain_mm_h": 2.5, "temperature_c": -9.0},
    )
    await rig.inject("/faults/estop", {"on": True})
    rig.world.base.panels.position = 0.5
    rig.world.base.lift.position = 0.25
    # The daemon reads discrete inputs and input registers in separate requests: wait for both
    # blocks to show the moved axes, or a snapshot can pair 25 % with a stale lower limit switch.
    await eventually(
        lambda: (
            (plc := rig.app.coordinator.snapshot.plc).estop_active
            and plc.wind_speed_mps == 11.0
            and plc.lift_position_pct == 25.0
            and not plc.panels_closed_limit
            and not plc.lift_down_limit
        ),
        what="E-stop, weather, and both axes off their low limits in one snapshot",
    )
    result = await run(rig.station, "check_availability")
    assert result.status is Status.REJECTED and not result.data["available"]
    failed = {c["name"]: c for c in result.data["failed"]}
    assert set(failed) == {
        "wind",
        "gust",
        "rain",
        "temperature_min",
        "estop",
        "faults",
        "panels_closed",
        "lift_down",
        "uav_present",
    }
    assert (failed["wind"]["value"], failed["wind"]["limit"]) == (11.0, 8.0)
    assert (failed["gust"]["value"], failed["gust"]["limit"]) == (16.0, 12.0)
    assert (failed["rain"]["value"], failed["rain"]["limit"]) == (2.5, 0.0)
    assert (failed["temperature_min"]["value"], failed["temperature_min"]["limit"]) == (
        -9.0,
        -5.0,
    )
    assert failed["faults"]["value"] == "ESTOP"
    assert failed["panels_closed"]["value"] == 50.0 and failed["lift_down"]["value"] == 25.0
    assert failed["uav_present"]["limit"] == "1200..1800 g"
    for text in (
        "wind 11.0 m/s (max 8.0)",
        "gust 16.0 m/s",
        "rain 2.5 mm/h",
        "-9.0 °C",
        "E-stop active",
        "panels 50 % open",
        "lift 25 % up",
        "outside UAV window",
    ):
        assert text in result.reason


async def test_weather_sensor_fault_fails_availability(rig: Rig) -> None:
    await rig.inject("/pad", {"mass_g": 1500})
    await rig.inject("/faults/weather_sensor", {"on": True})
    await eventually(
        lambda: (
            "weather_sensor_fault" in rig.station.telemetry().faults.names
            and rig.station.telemetry().uav_present is True
        ),
        what="sensor fault and UAV seen",
    )
    result = await run(rig.station, "check_availability")
    names = {c["name"] for c in result.data["failed"]}
    assert names == {"weather_sensor", "faults"}
    assert rig.station.telemetry().faults.bits & FaultBit.WEATHER_SENSOR
    # a dead anemometer does not stop the base from closing
    assert (await run(rig.station, "open_panels")).status is Status.SUCCEEDED


async def test_landing_confirmed_only_after_stable_window(rig: Rig) -> None:
    async with rig.station.subscribe() as events:
        await rig.inject("/pad", {"mass_g": 1500, "contacts_seated": True})
        await eventually(lambda: rig.station.telemetry().uav_present is True, what="present")
        seen_present = asyncio.get_running_loop().time()
        event = await asyncio.wait_for(_first(events, EventKind.LANDING_CONFIRMED), 5)
        # confirmation needs the mass to stay in the window for stable_s (0.5 s)
        assert asyncio.get_running_loop().time() - seen_present >= 0.4
        assert 1480 <= event.data["mass_g"] <= 1520
    tel = rig.station.telemetry()
    assert tel.landing_confirmed and 1480 <= tel.scale_mass_g <= 1520
    await rig.inject("/pad", {"mass_g": 0})
    await eventually(lambda: rig.station.telemetry().landing_confirmed is False, what="gone")


async def test_mass_outside_the_window_is_never_confirmed(rig: Rig) -> None:
    await rig.inject("/pad", {"mass_g": 2600})
    await eventually(lambda: rig.app.coordinator.polls >= 30, what="30 polls (1.5 s)")
    tel = rig.station.telemetry()
    assert tel.uav_present is False and tel.landing_confirmed is False
    assert EventKind.LANDING_CONFIRMED not in [e.kind for e in rig.app.coordinator.events.history]


async def _first(events, kind):  # type: ignore[no-untyped-def]
    async for e in events:
        if e.kind is kind:
            return e
    return None


async def test_start_charging_refused_without_contacts_or_with_lift_up(rig: Rig) -> None:
    result = await run(rig.station, "start_charging")
    assert result.status is Status.REJECTED and "UAV contacts not seated" in result.reason
    await rig.inject("/pad", {"mass_g": 1500, "contacts_seated": True, "uav_soc": 0.5})
    assert (await run(rig.station, "open")).status is Status.SUCCEEDED
    result = await run(rig.station, "start_charging")
    assert (
        result.status is Status.REJECTED and "lift is 100 % up, must be fully down" in result.reason
    )


@pytest.mark.slow
async def test_charging_cc_cv_to_completion_with_limit_and_power_source() -> None:
    async with rig_at(speed=400.0) as rig:
        await rig.inject("/weather/force", {"rain_mm_h": 2.0})  # clouds: solar cannot cover it
        await rig.inject("/pad", {"mass_g": 1500, "contacts_seated": True, "uav_soc": 0.88})
        await eventually(lambda: rig.station.telemetry().charger.contact, what="contacts")
        samples: list[tuple[str | None, int, float | None]] = []
        async with rig.station.subscribe() as events:
            result = await run(rig.station, "start_charging", {"current_limit_ma": 4000})
            assert result.status is Status.SUCCEEDED, result.reason
            done = asyncio.ensure_future(_first(events, EventKind.CHARGE_COMPLETE))
            while not done.done():
                c = rig.station.telemetry().charger
                samples.append((c.state, round((c.current_a or 0) * 1000), c.uav_battery_pct))
                await asyncio.wait([done], timeout=0.05)
            event = done.result()
        assert event.data["uav_battery_pct"] >= 99.0
        charging = [s for s in samples if s[0] == "charging"]
        assert charging[0][1] == 4000  # constant current at the limit
        cv = [i for _, i, _ in charging if i < 4000]
        assert cv and cv == sorted(cv, reverse=True) and cv[-1] < 1000  # tapering in CV
        assert rig.station.telemetry().charger.state == "complete"
        sources = [
            e.data["source"]
            for e in rig.app.coordinator.events.history
            if e.kind is EventKind.POWER_SOURCE_CHANGED
        ]
        assert "grid" in sources
        assert (await run(rig.station, "stop_charging")).status is Status.SUCCEEDED
        await eventually(lambda: rig.station.telemetry().charger.state == "idle")


async def test_charger_fault_refuses_charging_and_is_reported(rig: Rig) -> None:
    await rig.inject("/pad", {"mass_g": 1500, "contacts_seated": True, "uav_soc": 0.5})
    await rig.inject("/faults/charger", {"on": True})
    await rig.inject("/faults/grid", {"present": False})
    await eventually(
        lambda: "charger_fault" in rig.station.telemetry().faults.names, what="charger fault"
    )
    await eventually(lambda: rig.station.telemetry().charger.contact, what="contacts")
    result = await run(rig.station, "start_charging")
    assert result.status is Status.REJECTED and "charger fault" in result.reason
    assert any(
        e.kind is EventKind.FAULT and "CHARGER" in e.data["faults"]
        for e in rig.app.coordinator.events.history
    )
    await eventually(lambda: rig.station.telemetry().power.grid_present is False, what="grid off")


@pytest.mark.slow
async def test_a_charger_that_never_starts_fails_with_why_while_the_daemon_keeps_polling() -> None:
    """Contacts seated but no battery link to the pack: the charger stays idle. start_charging fails
    after its window saying why, and all the while the daemon keeps polling the PLC and feeding its
    watchdog (the wait once re-read the same snapshot without awaiting and froze the event loop)."""
    async with World(WorldConfig.for_tests(speed=SPEED, seed=5)) as world:
        world.weather.force(wind_mps=2.0, gust_mps=3.0, rain_mm_h=0.0, temperature_c=15.0)
        config = station_config(world.ports["plc"], SPEED)
        config = config.model_copy(
            update={"charge": config.charge.model_copy(update={"start_timeout_s": 2.0})}
        )
        app = await start_daemon(config)
        try:
            await eventually(lambda: app.coordinator.snapshot.link_up, 5.0, "link up")
            await eventually(lambda: world.base.watchdog_armed, 5.0, "watchdog armed")
            world.base.set_pad_load(1500, contacts_seated=True)  # a pack the charger cannot talk to
            await eventually(lambda: app.station.telemetry().charger.contact, what="contacts")
            polls = app.coordinator.polls
            result = await run(app.station, "start_charging")
            assert result.status is Status.FAILED
            assert "within 2 s" in result.reason and "charger idle" in result.reason
            assert "no battery link" in result.reason, result.reason
            assert app.coordinator.polls - polls >= 10  # 20 Hz for 2 s: the poll loop went on
            assert "WATCHDOG" not in app.coordinator.snapshot.plc.fault_names
        finally:
            await stop_daemon(app)
