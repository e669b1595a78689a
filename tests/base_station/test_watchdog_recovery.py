"""A watchdog latch left by a killed or frozen daemon is recovered when (and only when) it is safe.

The PLC (spec rev. A, holding register 0) stops all motion and latches fault 16 when its master
writes no new watchdog value for 2 s; the latch refuses every motion until FAULT_RESET. A daemon
killed while the panels were opening used to come back to a PLC that refused `close` for good.
"""

from __future__ import annotations

import asyncio

import pytest
from bs_helpers import Rig, rig_at, run, start_daemon, station_config

from base_station.events import EventKind
from base_station.plc import FaultBit
from base_station.station import Status
from tests.polling import eventually

pytestmark = pytest.mark.slow  # the PLC's watchdog takes 2 s of wall time to expire

MOTION = {"PANELS_OPEN", "PANELS_CLOSE", "LIFT_UP", "LIFT_DOWN"}


async def _kill_mid_open(rig: Rig) -> None:
    """Open the panels, kill the daemon at ~30 %, wait for the PLC to latch its watchdog."""
    motion = asyncio.ensure_future(run(rig.station, "open"))
    await eventually(lambda: rig.world.base.panels.position > 0.3, what="panels 30 % open")
    motion.cancel()
    await rig.app.coordinator.stop()  # killed: no MOTION_STOP, no more watchdog values
    base = rig.world.base
    await eventually(lambda: base.fault_bits() & FaultBit.WATCHDOG, 5.0, "the PLC's watchdog latch")
    assert not base.panels.moving and not base.lift.moving


async def test_a_daemon_restarted_after_a_kill_mid_open_clears_the_latch_and_can_close() -> None:
    speed = 3.0  # panels take 4 s of wall time: the watchdog trips before they are open
    async with rig_at(speed=speed) as rig:
        await _kill_mid_open(rig)
        before = len(rig.world.base.command_log)
        rig.app = await start_daemon(station_config(rig.world.ports["plc"], speed))
        await rig.link_up()
        base = rig.world.base
        await eventually(lambda: base.fault_bits() == 0, 5.0, "the latch cleared by the daemon")
        written = [c.coil for c in base.command_log[before:]]
        assert written == ["FAULT_RESET"], written  # recovery moves nothing by itself
        assert not base.panels.moving and 0.0 < base.panels.position < 1.0
        # the event is recorded once the PLC has answered the write, which clears the latch
        # first: the PLC's clear may be seen before the daemon has the answer
        await eventually(
            lambda: any(
                e.kind is EventKind.WATCHDOG_RECOVERED for e in rig.app.coordinator.events.history
            ),
            5.0,
            "the recovery recorded as an event",
        )
        closed = await run(rig.station, "close")
        assert closed.status is Status.SUCCEEDED, closed.reason
        assert base.panels.at_low and base.lift.at_low


async def test_a_close_arriving_before_the_poll_loop_recovers_clears_the_latch_itself() -> None:
    speed = 3.0
    async with rig_at(speed=speed) as rig:
        await _kill_mid_open(rig)
        rig.app = await start_daemon(station_config(rig.world.ports["plc"], speed))
        await rig.link_up()  # the first read: the latch is still there, the watchdog not yet fed
        closed = await run(rig.station, "close")  # the run's safe close, replayed at once
        assert closed.status is Status.SUCCEEDED, closed.reason
        assert rig.world.base.panels.at_low


async def test_a_stall_latched_with_the_watchdog_is_left_for_a_person() -> None:
    speed = 3.0
    async with rig_at(speed=speed) as rig:
        await _kill_mid_open(rig)
        rig.world.base.inject_stall("lift", immediate=True)  # a second, real fault
        before = len(rig.world.base.command_log)
        rig.app = await start_daemon(station_config(rig.world.ports["plc"], speed))
        await rig.link_up()
        await eventually(lambda: rig.app.coordinator.watchdog.writes >= 8, what="watchdog fed 2 s")
        closed = await run(rig.station, "close")
        assert closed.status is Status.REJECTED and "LIFT_STALL" in closed.reason, closed.reason
        assert [c.coil for c in rig.world.base.command_log[before:]] == []  # no FAULT_RESET
        assert rig.world.base.fault_bits() & FaultBit.WATCHDOG


async def test_an_estop_keeps_the_watchdog_latch() -> None:
    speed = 3.0
    async with rig_at(speed=speed) as rig:
        await _kill_mid_open(rig)
        rig.world.base.set_estop(True)
        rig.world.base.set_estop(False)  # released, but its latch (32) needs a person's reset
        before = len(rig.world.base.command_log)
        rig.app = await start_daemon(station_config(rig.world.ports["plc"], speed))
        await rig.link_up()
        await eventually(lambda: rig.app.coordinator.watchdog.writes >= 8, what="watchdog fed 2 s")
        assert [c.coil for c in rig.world.base.command_log[before:]] == []
        assert (await run(rig.station, "close")).status is Status.REJECTED
