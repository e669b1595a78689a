"""Panels and lift through the daemon, over real Modbus TCP against the simulated PLC."""

from __future__ import annotations

import asyncio

import pytest
from bs_helpers import Rig, run

from base_station.events import EventKind
from base_station.station import Progress, Result, Status
from tests.polling import eventually


@pytest.mark.slow
async def test_full_open_then_close_cycle_with_progress(rig: Rig) -> None:
    items = [i async for i in rig.station.execute("open", {})]
    result = items[-1]
    assert isinstance(result, Result) and result.status is Status.SUCCEEDED, result
    steps = [i.step for i in items if isinstance(i, Progress)]
    assert steps[0] == "open_panels" and "lift_up" in steps
    assert steps.index("lift_up") > steps.index("panels_moving")
    assert rig.world.base.can_vehicle_leave()
    tel = rig.station.telemetry()
    assert tel.panels.state == "open" and tel.lift.state == "open"
    assert tel.panels.position_pct == 100.0 and tel.lift.position_pct == 100.0

    result = await run(rig.station, "close")
    assert result.status is Status.SUCCEEDED, result
    base = rig.world.base
    assert base.panels.at_low and base.lift.at_low
    assert rig.commands() == ["PANELS_OPEN", "LIFT_UP", "LIFT_DOWN", "PANELS_CLOSE"]
    assert rig.station.telemetry().panels.state == "closed"


async def test_lift_up_refused_by_daemon_with_panels_partly_open(rig: Rig) -> None:
    rig.world.base.panels.position = 0.4  # stopped mid-way
    await eventually(lambda: rig.app.coordinator.snapshot.plc.panel_position_pct == 40.0)
    async with rig.station.subscribe() as events:
        result = await run(rig.station, "lift_up")
        assert result.status is Status.REJECTED
        assert "lift up refused: panels are 40 % open, must be fully open" in result.reason
        event = await asyncio.wait_for(events.__anext__(), 2)
        assert event.kind is EventKind.REFUSAL and "40 % open" in event.message
    assert rig.commands() == []  # nothing was written to the PLC


async def test_close_panels_refused_by_daemon_with_lift_up(rig: Rig) -> None:
    assert (await run(rig.station, "open")).status is Status.SUCCEEDED
    result = await run(rig.station, "close_panels")
    assert result.status is Status.REJECTED
    assert "lift is 100 % up, must be fully down" in result.reason
    assert rig.commands() == ["PANELS_OPEN", "LIFT_UP"]


async def test_motion_refused_while_estop_and_while_fault_latched(rig: Rig) -> None:
    await rig.inject("/faults/estop", {"on": True})
    await eventually(lambda: rig.app.coordinator.snapshot.plc.estop_active)
    result = await run(rig.station, "open_panels")
    assert result.status is Status.REJECTED and "E-stop active" in result.reason
    await rig.inject("/faults/estop", {"on": False})
    await eventually(lambda: not rig.app.coordinator.snapshot.plc.estop_active)
    result = await run(rig.station, "open_panels")
    assert result.status is Status.REJECTED and "faults latched: ESTOP" in result.reason
    result = await run(rig.station, "reset_faults")
    assert result.status is Status.SUCCEEDED, result
    assert (await run(rig.station, "open_panels")).status is Status.SUCCEEDED
    assert rig.commands() == ["FAULT_RESET", "PANELS_OPEN"]


async def test_duplicate_command_does_not_start_a_second_motion(rig: Rig) -> None:
    first = asyncio.ensure_future(run(rig.station, "open_panels"))
    await eventually(lambda: rig.world.base.panels.moving, what="panels moving")
    second = await run(rig.station, "open_panels")
    assert second.status is Status.REJECTED and "busy: open_panels in progress" in second.reason
    assert (await first).status is Status.SUCCEEDED
    replay = await run(rig.station, "open_panels")  # replayed after completion
    assert replay.status is Status.SUCCEEDED and replay.reason == "panels already open"
    assert rig.commands() == ["PANELS_OPEN"]


async def test_command_refused_when_axis_already_moving_from_elsewhere(rig: Rig) -> None:
    rig.world.base.write_coils(0, [True])  # someone else started the panels
    await eventually(lambda: rig.app.coordinator.snapshot.plc.panels_moving)
    result = await run(rig.station, "open_panels")
    assert result.status is Status.REJECTED and "panels already moving" in result.reason
    assert rig.commands() == ["PANELS_OPEN"]


async def test_stop_mid_motion_and_in_every_state(rig: Rig) -> None:
    motion = asyncio.ensure_future(run(rig.station, "open_panels"))
    await eventually(lambda: rig.world.base.panels.position > 0.2, what="panels 20 % open")
    stop = await run(rig.station, "stop")
    assert stop.status is Status.SUCCEEDED
    result = await motion
    assert result.status is Status.FAILED and "stopped by operator" in result.reason
    assert not rig.world.base.panels.moving and 0 < rig.world.base.panels.position < 1
    await rig.inject("/faults/estop", {"on": True})
    await eventually(lambda: rig.app.coordinator.snapshot.plc.estop_active)
    assert (await run(rig.station, "stop")).status is Status.SUCCEEDED  # stop under E-stop too


async def test_unknown_command_and_bad_params_are_rejected_not_raised(rig: Rig) -> None:
    assert (await run(rig.station, "fly_away")).status is Status.REJECTED
    bad = await run(rig.station, "start_charging", {"current_limit_ma": "lots"})
    assert bad.status is Status.REJECTED and "current_limit_ma" in bad.reason
    assert rig.commands() == []
