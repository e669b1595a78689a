"""Injected faults end in their safe outcome: stall, E-stop, link cut/freeze, watchdog, restart."""

from __future__ import annotations

import asyncio

import pytest
from bs_helpers import Rig, rig_at, run, start_daemon, station_config, stop_daemon

from base_station.events import EventKind
from base_station.outcomes import Item, Progress, Result
from base_station.plc import FaultBit
from base_station.station import Status
from tests.polling import eventually


def kinds(rig: Rig) -> list[EventKind]:
    return [e.kind for e in rig.app.coordinator.events.history]


async def test_stall_while_opening_stops_reports_and_never_raises_the_lift(rig: Rig) -> None:
    await rig.inject("/faults/stall", {"axis": "panels", "on": True})
    async with rig.station.subscribe() as events:
        result = await run(rig.station, "open")
        assert result.status is Status.FAILED
        assert result.reason.startswith("open_panels: panels motor stall at 0 %"), result.reason
        seen = [e async for e in _drain(events)]
    assert any(e.kind is EventKind.FAULT and "PANEL_STALL" in e.message for e in seen)
    assert any(e.kind is EventKind.MOTION_FAILED for e in seen)
    base = rig.world.base
    assert not base.panels.moving and base.lift.position == 0.0 and not base.lift.moving
    assert "LIFT_UP" not in rig.commands()
    assert rig.station.telemetry().panels.state == "fault"
    # the lift stays refused until the fault is reset
    assert (await run(rig.station, "lift_up")).status is Status.REJECTED


async def _drain(events):  # type: ignore[no-untyped-def]
    while not events.queue.empty():
        yield events.queue.get_nowait()


async def test_estop_mid_motion_stops_and_fails_the_command(rig: Rig) -> None:
    motion = asyncio.ensure_future(run(rig.station, "open_panels"))
    await eventually(lambda: rig.world.base.panels.position > 0.2, what="panels moving")
    await rig.inject("/faults/estop", {"on": True})
    result = await motion
    assert result.status is Status.FAILED and "E-stop" in result.reason
    assert not rig.world.base.panels.moving
    # the E-stop input is read (discrete inputs) before the fault register, by separate Modbus
    # requests: pressed between them, the poll sees the fault (which fails the motion) and the
    # next one the E-stop, whose event comes then
    await eventually(lambda: EventKind.ESTOP in kinds(rig), what="the estop event")
    fault_events = [e for e in rig.app.coordinator.events.history if e.kind is EventKind.FAULT]
    assert any("ESTOP" in e.data["faults"] for e in fault_events)
    reset = await run(rig.station, "reset_faults")
    assert reset.status is Status.FAILED and "E-stop still active" in reset.reason


def waiting_for_the_link(rig: Rig, seconds: float) -> None:
    """The daemon's motion commands wait `seconds` for a PLC link found down ([motion])."""
    config = rig.app.station.config
    motion = config.motion.model_copy(update={"link_wait_s": seconds})
    rig.app.station.config = config.model_copy(update={"motion": motion})


async def test_link_cut_is_reported_and_motion_refused_then_restored_without_motion(
    rig: Rig,
) -> None:
    waiting_for_the_link(rig, 0.3)  # refused once that wait is over
    before = rig.commands()
    await rig.inject("/faults/link", {"mode": "cut"})
    await rig.link_up(False)
    assert EventKind.PLC_LINK_LOST in kinds(rig)
    result = await run(rig.station, "open_panels")
    assert result.status is Status.REJECTED and "PLC link down" in result.reason
    assert rig.station.telemetry().plc_link == "down"
    avail = await run(rig.station, "check_availability")
    assert avail.status is Status.REJECTED and "PLC link down" in avail.reason
    await rig.inject("/faults/link", {"mode": "normal"})
    await rig.link_up(True)
    assert EventKind.PLC_LINK_RESTORED in kinds(rig)
    assert rig.commands() == before  # reconnecting wrote no command
    assert not rig.world.base.panels.moving and not rig.world.base.lift.moving


async def test_link_freeze_is_detected_by_timeout_and_motion_refused(rig: Rig) -> None:
    waiting_for_the_link(rig, 0.3)
    await rig.inject("/faults/link", {"mode": "freeze"})
    await rig.link_up(False)
    assert "failed" in rig.app.coordinator.snapshot.link_error
    result = await run(rig.station, "lift_down")
    assert result.status is Status.REJECTED and "PLC link down" in result.reason
    await rig.inject("/faults/link", {"mode": "normal"})
    await rig.link_up(True)


async def test_a_motion_command_in_a_link_blip_waits_for_the_link_then_runs(rig: Rig) -> None:
    """A close sent while the link is down for a moment (a missed poll, a frozen heartbeat) was
    refused at once, and the run failed with the UAV on the lift. Now it waits for the link
    (`[motion] link_wait_s`), saying so, and runs on the fresh reading's checks."""
    waiting_for_the_link(rig, 20.0)
    await rig.inject("/faults/link", {"mode": "cut"})
    await rig.link_up(False)
    items: list[Item] = []

    async def command() -> None:
        async for item in rig.station.execute("open_panels"):
            items.append(item)

    motion = asyncio.ensure_future(command())
    told = "PLC link down: waiting up to 20 s for it"
    await eventually(lambda: any(isinstance(i, Progress) and i.message == told for i in items))
    assert not motion.done() and "PANELS_OPEN" not in rig.commands()  # nothing written meanwhile
    await rig.inject("/faults/link", {"mode": "normal"})
    await asyncio.wait_for(motion, 20)
    result = items[-1]
    assert isinstance(result, Result) and result.status is Status.SUCCEEDED, result
    assert rig.station.telemetry().panels.state == "open"


async def test_a_link_blip_mid_motion_is_waited_out_and_the_motion_completes() -> None:
    """The link lost for a moment while the panels open (under its PLC watchdog's 2 s: the motor
    goes on). The command failed at once, the motion went on unwatched, and the run's close of
    the base was refused ("panels already moving"). Now the loss is waited out and the motion
    followed to its end."""
    async with rig_at(speed=3.0) as rig:  # panels take 4 s wall
        waiting_for_the_link(rig, 20.0)
        motion = asyncio.ensure_future(run(rig.station, "open_panels"))
        await eventually(lambda: rig.world.base.panels.moving, what="panels moving")
        await rig.inject("/faults/link", {"mode": "cut"})
        await rig.link_up(False)
        await rig.inject("/faults/link", {"mode": "normal"})
        result = await asyncio.wait_for(motion, 20)
        assert result.status is Status.SUCCEEDED, result
        assert rig.station.telemetry().panels.state == "open"
        assert not rig.world.base.fault_bits() & FaultBit.WATCHDOG  # the blip was a blip


@pytest.mark.slow
async def test_link_cut_mid_motion_fails_it_and_the_plc_watchdog_stops_the_motor() -> None:
    async with rig_at(speed=3.0) as rig:  # panels take 4 s wall: longer than the watchdog
        motion = asyncio.ensure_future(run(rig.station, "open_panels"))
        await eventually(lambda: rig.world.base.panels.moving, what="panels moving")
        await rig.inject("/faults/link", {"mode": "cut"})
        result = await motion
        assert result.status is Status.FAILED and "PLC link lost" in result.reason
        await eventually(lambda: not rig.world.base.panels.moving, 5.0, "PLC stops the motor")
        assert rig.world.base.fault_bits() & FaultBit.WATCHDOG, rig.world.base.ground_truth()
        assert rig.world.base.panels.position < 1.0


@pytest.mark.slow
async def test_watchdog_expires_when_the_daemon_freezes() -> None:
    async with rig_at(speed=3.0) as rig:
        motion = asyncio.ensure_future(run(rig.station, "open_panels"))
        await eventually(lambda: rig.world.base.panels.moving, what="panels moving")
        rig.app.coordinator.watchdog.pause()  # the daemon stops feeding the PLC
        result = await motion
        assert result.status is Status.FAILED and "WATCHDOG latched" in result.reason
        assert not rig.world.base.panels.moving and rig.world.base.panels.position < 1.0
        assert any(
            e.kind is EventKind.FAULT and "WATCHDOG" in e.data["faults"]
            for e in rig.app.coordinator.events.history
        )
        wd = rig.app.coordinator.watchdog
        writes = wd.writes
        wd.resume()
        await eventually(lambda: wd.writes > writes, what="watchdog fed again")
        assert (await run(rig.station, "reset_faults")).status is Status.SUCCEEDED
        assert rig.world.base.fault_bits() == 0


async def test_restart_mid_state_starts_no_motion(rig: Rig) -> None:
    motion = asyncio.ensure_future(run(rig.station, "open_panels"))
    await eventually(lambda: rig.world.base.panels.position > 0.3, what="panels 30 % open")
    await run(rig.station, "stop")
    await motion
    before = rig.commands()
    # crash: the old daemon just disappears, a new one starts on the same config
    await rig.app.coordinator.stop()
    rig.app = await start_daemon(station_config(rig.world.ports["plc"]))
    await rig.link_up()
    await eventually(lambda: rig.app.coordinator.polls >= 10, what="ten polls")
    snap = rig.app.coordinator.snapshot
    assert snap.plc.pending_commands == () and not snap.plc.panels_moving
    assert not snap.plc.lift_moving and rig.commands() == before
    assert rig.station.telemetry().panels.state == "stopped"


async def test_restart_while_moving_starts_nothing_new() -> None:
    async with rig_at(speed=3.0) as rig:
        motion = asyncio.ensure_future(run(rig.station, "open_panels"))
        await eventually(lambda: rig.world.base.panels.moving, what="panels moving")
        motion.cancel()
        await rig.app.coordinator.stop()  # crash mid-motion
        old = rig.app
        rig.app = await start_daemon(station_config(rig.world.ports["plc"], 3.0))
        await stop_daemon(old)
        await rig.link_up()
        await eventually(lambda: rig.app.coordinator.polls >= 5, what="five polls")
        assert rig.commands() == ["PANELS_OPEN"]
        assert rig.station.telemetry().panels.state in ("moving", "opening", "open")
        replay = await run(rig.station, "open_panels")  # replayed by a reconnecting server
        assert replay.status in (Status.REJECTED, Status.SUCCEEDED)
        assert rig.commands() == ["PANELS_OPEN"]


async def test_plc_cpu_halt_is_seen_through_the_frozen_heartbeat(rig: Rig) -> None:
    motion = asyncio.ensure_future(run(rig.station, "open_panels"))
    await eventually(lambda: rig.world.base.panels.moving, what="panels moving")
    await rig.inject("/faults/cpu_halt", {"on": True})
    result = await motion  # outputs drop: the motion fails whichever is seen first
    assert result.status is Status.FAILED
    await rig.link_up(False)
    assert "heartbeat frozen" in rig.app.coordinator.snapshot.link_error
    assert (await run(rig.station, "open_panels")).status is Status.REJECTED
    await rig.inject("/faults/cpu_halt", {"on": False})
    await rig.link_up(True)
    assert rig.commands() == ["PANELS_OPEN"]


async def test_telemetry_stream_yields_samples(rig: Rig) -> None:
    stream = rig.station.telemetry_stream(hz=50.0)
    samples = [await stream.__anext__() for _ in range(3)]
    await stream.aclose()
    assert all(s.plc_link == "up" and s.power is not None for s in samples)
