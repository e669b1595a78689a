"""Reboot detection (autopilot/boot.py) over a real MAVLink link to the simulated autopilot in
its own process: messages read late — the agent stopped, a radio's buffer — are not a reboot; a
reboot is, whether its uptime starts again or the link was down for longer than it."""

from __future__ import annotations

import asyncio
import time
from pathlib import Path

import pytest

from asset_agent.autopilot import Autopilot
from asset_agent.autopilot.boot import BootWatch
from tests.asset_agent.conftest import fast_config
from tests.e2e.test_demo_external import start_autopilot
from tests.polling import eventually

pytestmark = pytest.mark.slow  # an autopilot process, seconds of real link


async def test_messages_read_late_are_not_a_reboot_and_a_reboot_is(tmp_path: Path):
    proc, url, _ = start_autopilot(tmp_path, "ardupilot-4")
    ap = Autopilot(fast_config(url, link_timeout_s=10.0))
    notes = ap.subscribe()
    try:
        await ap.start()
        await eventually(lambda: ap.state.lat is not None and ap.state.roll_deg is not None, 10)
        time.sleep(2.5)  # noqa: ASYNC251  (the fault: the agent stopped, the autopilot sends on)
        with ap.tap(lambda m: m.get_type() == "SYSTEM_TIME") as q:
            for _ in range(4):  # the backlog read, then four seconds of SYSTEM_TIME on time
                await asyncio.wait_for(q.get(), 5)
        assert ap.reboots == 0
        texts = [notes.get_nowait().text for _ in range(notes.qsize())]
        assert "autopilot rebooted" not in texts
        await ap.reboot()
        await eventually(lambda: ap.reboots == 1, 20, "the reboot seen")
    finally:
        await ap.close()
        proc.terminate()
        proc.wait(10)


def test_uptime_going_back_is_a_reboot_at_once():
    w = BootWatch()
    assert w.check(100_000, 1000.0) is None
    assert w.check(100_200, 1000.2) is None
    assert "uptime went back" in (w.check(3_000, 1000.4) or "")
    assert w.check(3_200, 1000.6) is None  # the new boot: on time


def test_a_later_boot_instant_is_a_reboot_once_it_stays():
    """A link down 60 s across a reboot 45 s in: the uptime (15 s) has not gone back, the boot
    instant is 50 s later and stays there."""
    w = BootWatch()
    assert w.check(5_000, 1000.0) is None
    t, uptime, seen = 1060.0, 15_000, []
    while t < 1064.0:
        seen.append(w.check(uptime, t))
        t, uptime = t + 0.5, uptime + 500
    assert seen[0] is None  # what a backlog's first message looks like
    assert seen[1] is not None and "50.0 s later" in seen[1]  # still later half a second on
    assert seen[2:] == [None] * (len(seen) - 2)
