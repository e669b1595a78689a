"""The simulated autopilot's own loop on a starved process: its clock falls behind, as SITL's does,
instead of flying the starved time in one step (sim/vehicle/server.py, MAX_CATCH_UP_WALL_S)."""

from __future__ import annotations

import time

from sim.vehicle.server import MAX_CATCH_UP_WALL_S, run_vehicle
from tests.polling import eventually

SPEED = 2.0


async def test_a_starved_autopilot_flies_no_more_than_sitl_would_catch_up():
    async with run_vehicle(speed=SPEED, seed=3) as sim:
        await eventually(lambda: sim.copter.t > 0.5, within=10, what="the vehicle's loop running")
        before, behind_before = sim.copter.t, sim.behind_s
        # the process starved: no step, no message read, for a wall second (blocking on purpose)
        time.sleep(1.0)  # noqa: ASYNC251
        woke = time.monotonic()
        await eventually(lambda: sim.copter.t > before, within=5, what="a step after the stall")
        flown = sim.copter.t - before
        # 2 s of the clock went by; a step covers at most its sleep and 0.1 s more (at 2x), and
        # the steps since the stall ended no more than the wall time since, at 2x
        most = (sim.step_s + MAX_CATCH_UP_WALL_S) * SPEED
        assert flown <= most + (time.monotonic() - woke) * SPEED, flown
        assert sim.behind_s - behind_before >= 2.0 - most - 0.2, sim.behind_s
        # and it goes on at the clock's speed from there
        t0, w0 = sim.copter.t, time.monotonic()
        await eventually(lambda: sim.copter.t >= t0 + 1.0, within=10, what="1 s more flown")
        assert sim.copter.t - t0 <= (time.monotonic() - w0) * SPEED + most
