"""Reboot detection (autopilot/boot.py) over a real MAVLink link to the simulated autopilot in
its own process: messages read late — the agent stopped, a radio's buffer — are not a reboot, nor
is a SITL's clock falling behind, nor time_boot_ms wrapping after 49.7 days; a reboot is, whether
its uptime starts again or the link was down for longer than it."""

from __future__ import annotations

import asyncio
import contextlib
import os
import signal
import subprocess
import time
from collections.abc import AsyncIterator
from pathlib import Path

import pytest

from asset_agent.autopilot import Autopilot
from asset_agent.autopilot.boot import WRAP_MS, BootWatch
from sim.vehicle.copter import CopterConfig
from sim.vehicle.server import run_vehicle
from tests.asset_agent.conftest import fast_config
from tests.e2e.test_demo_external import SPEED, start_autopilot
from tests.polling import eventually

pytestmark = pytest.mark.slow  # an autopilot process, seconds of real link


@contextlib.asynccontextmanager
async def sitl(folder: Path) -> AsyncIterator[tuple[subprocess.Popen[bytes], Autopilot]]:
    """`aerobase sim autopilot` (ArduPilot 4, SITL's clock) in its own process, and an adapter
    connected to it whose link outlasts the faults below."""
    proc, url, _ = start_autopilot(folder, "ardupilot-4")
    ap = Autopilot(fast_config(url, link_timeout_s=10.0))
    try:
        await ap.start()
        await eventually(lambda: ap.state.lat is not None and ap.state.roll_deg is not None, 10)
        yield proc, ap
    finally:
        await ap.close()
        proc.terminate()
        proc.wait(10)


async def test_messages_read_late_are_not_a_reboot_and_a_reboot_is(tmp_path: Path):
    async with sitl(tmp_path) as (_, ap):
        notes = ap.subscribe()
        time.sleep(2.5)  # noqa: ASYNC251  (the fault: the agent stopped, the autopilot sends on)
        with ap.tap(lambda m: m.get_type() == "SYSTEM_TIME") as q:
            for _ in range(4):  # the backlog read, then four seconds of SYSTEM_TIME on time
                await asyncio.wait_for(q.get(), 5)
        assert ap.reboots == 0
        texts = [notes.get_nowait().text for _ in range(notes.qsize())]
        assert "autopilot rebooted" not in texts
        await ap.reboot()
        await eventually(lambda: ap.reboots == 1, 20, "the reboot seen")


def test_uptime_going_back_is_a_reboot_at_once():
    w = BootWatch()
    assert w.check(100_000, 1000.0) is None
    assert w.check(100_200, 1000.2) is None
    assert "uptime went back" in (w.check(3_000, 1000.4) or "")
    assert w.check(3_200, 1000.6) is None  # the new boot: on time


def test_an_uptime_short_of_the_time_since_is_a_reboot_once_it_stays():
    """A link down 60 s across a reboot 45 s in: the uptime (15 s) has not gone back; it is 50 s
    short of the old one's 5 s plus the 60 s since, and stays short."""
    w = BootWatch()
    assert w.check(5_000, 1000.0) is None
    t, uptime, seen = 1060.0, 15_000, []
    while t < 1064.0:
        seen.append(w.check(uptime, t))
        t, uptime = t + 0.5, uptime + 500
    assert seen[0] is None  # what a backlog's first message looks like
    assert seen[1] is not None and "50.0 s short" in seen[1]  # still short half a second on
    assert seen[2:] == [None] * (len(seen) - 2)


async def test_a_sitl_whose_clock_fell_behind_has_not_rebooted(tmp_path: Path):
    """The simulated autopilot keeps SITL's clock (simulated time since boot); stopped 2 s, it
    loses that time for good, as a starved SITL does: its uptime is short from then on."""
    async with sitl(tmp_path) as (proc, ap):
        await eventually(lambda: (ap.boot.uptime_ms or 0) > 10_000, 15, "10 s of uptime")
        with ap.tap(lambda m: m.get_type() == "SYSTEM_TIME") as q:
            before = (time.monotonic(), (await asyncio.wait_for(q.get(), 5)).time_boot_ms)
            os.kill(proc.pid, signal.SIGSTOP)
            try:
                await asyncio.sleep(2.0)  # the fault's length: the autopilot starved this long
            finally:
                os.kill(proc.pid, signal.SIGCONT)
            while not q.empty():
                q.get_nowait()
            after = (time.monotonic(), (await asyncio.wait_for(q.get(), 5)).time_boot_ms)
            lost = (after[0] - before[0]) - (after[1] - before[1]) / 1000 / float(SPEED)
            assert lost > 1.5  # the premise: its clock fell behind the wall
            for _ in range(4):  # four more seconds of SYSTEM_TIME
                await asyncio.wait_for(q.get(), 5)
        assert ap.reboots == 0


def test_a_clock_at_half_the_walls_speed_has_not_rebooted():
    w = BootWatch()
    verdicts = [w.check(60_000 + i * 50, 1000.0 + i * 0.1) for i in range(600)]  # a minute
    assert verdicts == [None] * 600


def test_a_half_speed_clock_heard_again_after_an_outage_has_not_rebooted():
    """Early in its boot (1.5 s of uptime) a SITL at half the wall's speed goes unheard for 6 s:
    3 s of uptime in 6 s of arrivals is on time at its rate (taken as the wall's, 3 s short)."""
    w = BootWatch()
    verdicts = [w.check(500 + i * 50, 1000.0 + i * 0.1) for i in range(21)]  # 2 s heard
    verdicts += [w.check(4_500 + i * 50, 1008.0 + i * 0.1) for i in range(20)]  # after 6 s
    assert verdicts == [None] * 41


def test_a_fast_clocks_reboot_is_told_at_its_rate():
    """A SITL at 20x, 20 s of uptime, unheard for 3 s across a reboot: the new boot speaks at 40 s
    of uptime, more than the old had. At 20x, 3 s of arrivals are 60 s of its clock: 40 s short."""
    w = BootWatch()
    verdicts = [w.check(i * 2_000, 999.0 + i * 0.1) for i in range(11)]  # 0-20 s of uptime
    verdicts += [w.check(40_000 + i * 2_000, 1003.0 + i * 0.1) for i in range(8)]
    assert verdicts[:12] == [None] * 12  # the first message after: maybe a backlog
    told = [v for v in verdicts if v]
    assert len(told) == 1 and "40.0 s short" in told[0]  # half a second on, still short


def test_a_reboot_after_the_clock_starved_while_its_rate_was_taken_is_told():
    """A SITL at 20x, heard at 5 Hz, starved 0.5 s (2 s of its clock where 10 s were due) in the
    first 1.3 s of arrivals: its rate while it runs is still 20x (a mean over the window: 13.8x).
    Rebooted, it speaks 5 s on with 80 s of uptime, more than the old 38 s: 58 s short of the
    38 s plus 5 s at 20x. At 13.8x it would be 27 s short, less than the 38 s uptime: on time,
    and the new boot taken for the old for good (the CI failure of the habits reboot test)."""
    w = BootWatch()
    heard = [(1000.0, 20_000), (1000.2, 24_000), (1000.4, 28_000)]
    heard += [(1000.9, 30_000), (1001.1, 34_000), (1001.3, 38_000)]  # after the starving
    assert [w.check(ms, t) for t, ms in heard] == [None] * 6
    assert w.rate == pytest.approx(20.0)
    verdicts = [w.check(80_000 + i * 4_000, 1006.3 + i * 0.2) for i in range(10)]
    told = [v for v in verdicts if v]
    assert len(told) == 1 and "58.0 s short" in told[0], verdicts


def test_a_clock_that_lost_3_s_at_100_s_of_uptime_has_not_rebooted():
    w = BootWatch()
    assert w.check(100_000, 1000.0) is None
    verdicts = [w.check(100_100 + i * 100, 1003.1 + i * 0.1) for i in range(40)]
    assert verdicts == [None] * 40


def test_time_boot_ms_wrapping_after_49_7_days_is_not_a_reboot():
    """A uint32 of milliseconds wraps to 0 after 49.7 days of uptime: counted on, on time."""
    w = BootWatch()
    start = WRAP_MS - 2_000  # 2 s before the wrap, heard at 10 Hz for 6 s
    verdicts = [w.check((start + i * 100) % WRAP_MS, 1000.0 + i * 0.1) for i in range(60)]
    assert verdicts == [None] * 60
    assert w.uptime_ms == start + 59 * 100  # counted on past the wrap
    assert "uptime went back" in (w.check(1_500, 1006.1) or "")  # then a reboot, 1.5 s in


def test_a_reboot_just_before_or_after_the_wrap_is_still_a_reboot():
    """A new boot's first words, counted on past the wrap, would be ahead of the time since."""
    for before_wrap_ms in (5_000, -5_000):  # rebooted 5 s before the wrap, or 5 s after it
        w = BootWatch()
        for i in range(11):
            assert (
                w.check((WRAP_MS - before_wrap_ms - 1_000 + i * 100) % WRAP_MS, 999 + i * 0.1)
                is None
            )
        assert "uptime went back" in (w.check(2_000, 1000.5) or "")  # up again 2 s in


def test_a_reboot_across_a_long_outage_soon_after_the_wrap_is_told():
    """10 s past the wrap, the link down 60 s across a reboot: the new boot's 30 s of uptime has
    not gone back; it is 40 s short, more than the 10 s the clock had counted since the wrap."""
    w = BootWatch()
    verdicts = [w.check((WRAP_MS - 2_000 + i * 1_000) % WRAP_MS, 1000.0 + i) for i in range(13)]
    assert verdicts == [None] * 13  # through the wrap, 10 s on
    told = [w.check(30_000 + i * 100, 1072.0 + i * 0.1) for i in range(10)]
    assert told[0] is None and any(v and "40.0 s short" in v for v in told), told


async def test_an_autopilot_up_49_7_days_is_heard_through_the_wrap_without_a_reboot():
    """The simulated flight controller left powered 6 s short of the wrap: the agent hears its
    time_boot_ms go back to 0 and tells no reboot; a real reboot after it is told."""
    config = CopterConfig(seed=3, powered_s=WRAP_MS / 1000 - 6.0)
    async with run_vehicle(speed=1.0, config=config) as vehicle:
        ap = Autopilot(fast_config(f"udpout:127.0.0.1:{vehicle.udp_port}"))
        await ap.start()
        try:
            notes = ap.subscribe()
            await eventually(lambda: ap.boot.uptime_ms is not None, 5, "the first message")
            assert (ap.boot.uptime_ms or 0) < WRAP_MS  # the premise: heard before the wrap
            with ap.tap(lambda m: m.get_type() == "SYSTEM_TIME") as q:
                while (await asyncio.wait_for(q.get(), 10)).time_boot_ms > 3_000:
                    pass  # until the autopilot's own time_boot_ms has wrapped
                for _ in range(2):  # and two seconds on
                    await asyncio.wait_for(q.get(), 5)
            assert ap.reboots == 0 and (ap.boot.uptime_ms or 0) > WRAP_MS
            texts = [notes.get_nowait().text for _ in range(notes.qsize())]
            assert "autopilot rebooted" not in texts
            await ap.reboot()
            await eventually(lambda: ap.reboots == 1, 20, "the reboot after the wrap seen")
            assert (ap.boot.uptime_ms or WRAP_MS) < 60_000  # the new boot counts from 0
        finally:
            await ap.close()
