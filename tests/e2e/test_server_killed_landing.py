"""A server restart never costs the landing (issue 46 item 4).

The world's sensors' clock is restarted under the running agent before the flight (as when the
simulated world, or a camera and IR sensor, restart: their timestamps start again near 0), then
the server process dies during the landing and stays down 20 s. The agent owns the landing: the
camera and IR readings of the new epoch steer it (precland/clock.py), and the RTK corrections
come from the base's own stream on the site's network (base_station/rtcm_server.py), so the UAV
stays RTK fixed. A new server on the same database resumes the run to `completed`.

Before issue 46 the same flight lost both: every reading looked minutes old (no LANDING_TARGET),
the fix fell to a plain 3D fix within 3 s, and the UAV came down on GNSS 1.2-1.6 m off the pad.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import time
from collections.abc import AsyncIterator
from dataclasses import asdict, dataclass, field
from typing import Any

import httpx
import pytest

from tests.conftest import LiveServer, Tenant, test_settings
from tests.e2e.harness import FINAL, Platform, platform
from tests.e2e.test_autonomous_run import WHOLE_SEQUENCE, _on_the_pad
from tests.load import busy_processes
from tests.polling import eventually

pytestmark = [
    pytest.mark.slow,  # whole processes end to end: not in the fast lane
    pytest.mark.realtime,  # landing loops through the camera (tests/priority.py)
    # a run takes 60-140 s of wall time, more beside busy processes: over the suite's 180 s
    pytest.mark.timeout(420),
]

KILLED_S = 20.0  # wall seconds the server stays down, from the start of the descent
PAD_M = 0.05  # the charging contacts
RTK_FIXED = 6
RESTARTED_FROM_S = 900.0  # the world's sensors had counted 15 minutes when it restarted


@dataclass
class Figures:
    """What one flight measured (printed as a JSON line `issue46 figures`)."""

    speed: float
    busy: int
    pad_distance_m: float = -1.0
    fixes_in_flight: list[int] = field(default_factory=list)
    fixes_in_outage: list[int] = field(default_factory=list)
    targets_in_outage: int = 0
    targets_sent: int = 0
    clock_epochs: int = 0
    landed_in_outage: bool = False
    landing_path: str | None = None
    silent_warnings: int = 0
    state: str = ""
    alert: bool = False
    wall_s: float = 0.0


@contextlib.asynccontextmanager
async def fix_types(p: Platform) -> AsyncIterator[set[int]]:
    """The fix types the simulated UAV's GNSS reported while the block runs (every 50 ms)."""
    seen: set[int] = set()

    async def watch() -> None:
        while True:
            seen.add(int(p.copter.reading.fix_type))
            await asyncio.sleep(0.05)

    task = asyncio.create_task(watch())
    try:
        yield seen
    finally:
        task.cancel()
        with contextlib.suppress(asyncio.CancelledError):
            await task


async def restart_the_sensors_clock(p: Platform) -> None:
    """The world's sensors count 15 minutes, then start again from 0, under the running agent;
    each time the agent receives IR readings of the new count. On the old count the agent reads
    its clock, as a landing's loop does (the issue's agent had landed on the world before)."""
    lander = p.agent.lander
    for at in (RESTARTED_FROM_S, 0.0):
        p.world.restart_sensor_clocks(at)
        readings = lander.stats.ir_readings
        await eventually(lambda n=readings: lander.stats.ir_readings > n + 20, 20, "IR readings")
        lander.clock.now()


async def fly_with_the_server_killed(
    database_url: str, superuser_email: str, tmp_path: Any, speed: float, busy: int = 0
) -> Figures:
    """One run: the sensors' clock restarted, the server killed for 20 s from the start of the
    descent, then restarted; the figures of the flight."""
    figures = Figures(speed, busy)
    began = time.monotonic()
    server = LiveServer(test_settings(database_url)).start()
    restarted = None
    try:
        with httpx.Client(base_url=server.url) as sync_api:
            tenant = Tenant(sync_api, superuser_email, f"killed-{speed:g}x")
            async with platform(
                server.url, tenant, tmp_path, speed=speed, precland={}, local_rtk=True
            ) as p:
                lander = p.agent.lander
                assert lander is not None
                await restart_the_sensors_clock(p)
                await eventually(lambda: p.copter.reading.fix_type == RTK_FIXED, 30, "RTK fixed")
                run_id = await p.start_run()
                await p.wait_state(run_id, ("flying",), 60)
                async with fix_types(p) as in_flight:
                    await eventually(
                        lambda: p.agent.autopilot.state.landed_state == "LANDING",
                        300,
                        "the descent to the pad",
                    )
                    await asyncio.to_thread(server.stop)
                    sent = lander.stats.targets_sent
                    async with fix_types(p) as in_outage:
                        await asyncio.sleep(KILLED_S)  # the outage itself, not a wait for anything
                    figures.targets_in_outage = lander.stats.targets_sent - sent
                    figures.landed_in_outage = not p.copter.armed
                    restarted = await asyncio.to_thread(server.restarted)
                    await eventually(lambda: not p.copter.armed, 180, "the landing")
                figures.pad_distance_m = round(p.copter.pad_distance(), 4)
                figures.fixes_in_flight = sorted(in_flight)
                figures.fixes_in_outage = sorted(in_outage)
                figures.targets_sent = lander.stats.targets_sent
                figures.clock_epochs = lander.clock.epochs
                body = await p.wait_state(run_id, FINAL, 180)
                figures.state, figures.alert = body["state"], body["alert"]
                events = await p.uav_events()
                landed = [e for e in events if e["name"] == "landed"]
                figures.landing_path = landed[-1]["data"].get("landing_path") if landed else None
                figures.silent_warnings = sum(e["name"] == "precland_silent" for e in events)
                figures.wall_s = round(time.monotonic() - began, 1)
                print("issue46 figures", json.dumps(asdict(figures)))
                names = [e["name"] for e in events]
                _assert_landed_on_the_pad_and_completed(p, figures, body, names)
    finally:
        await asyncio.to_thread((restarted or server).stop)
    return figures


def _assert_landed_on_the_pad_and_completed(
    p: Platform, figures: Figures, body: dict[str, Any], names: list[str]
) -> None:
    seen = (figures, _on_the_pad(p))
    assert figures.fixes_in_flight == [RTK_FIXED], seen  # RTK fixed throughout
    assert figures.fixes_in_outage == [RTK_FIXED], seen
    assert figures.targets_in_outage > 20, seen  # LANDING_TARGET fed the autopilot meanwhile
    assert figures.landing_path in ("precision", "search-then-precision"), seen
    assert "landed_without_precision" not in names, seen
    assert figures.pad_distance_m < PAD_M, seen
    assert body["state"] == "completed", (body["reason"], body["timeline"], seen)
    # transitions only (a restarted server may note a lease takeover: from_state == to_state)
    states = [t["to_state"] for t in body["timeline"] if t["from_state"] != t["to_state"]]
    assert states == [*WHOLE_SEQUENCE, "completed"], states  # resumed, not restarted
    assert not body["alert"], (body["reason"], seen)  # charging started: the contacts seated
    # the scale confirmed it on the lift and the base closed over it
    assert p.world.base.pad_mass_g > 0 and not p.world.base.can_vehicle_leave(), seen


@pytest.mark.parametrize("speed", [2.0, 5.0])
async def test_server_killed_during_the_landing_the_uav_lands_on_the_pad_and_the_run_completes(
    database_url, superuser_email, tmp_path, speed: float
):
    await fly_with_the_server_killed(database_url, superuser_email, tmp_path, speed)


@pytest.mark.soak  # ten whole runs beside four spinning processes: `make soak`
@pytest.mark.parametrize("speed,run", [(s, r) for s in (2.0, 5.0) for r in range(5)])
async def test_server_killed_during_the_landing_on_a_busy_machine(
    database_url, superuser_email, tmp_path, speed: float, run: int
):
    with busy_processes(4):
        await fly_with_the_server_killed(database_url, superuser_email, tmp_path, speed, busy=4)
