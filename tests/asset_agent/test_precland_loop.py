"""The thin loop closed around the simulated world over real sockets: camera frames over TCP,
IR readings over UDP, detection in a worker thread, setpoints flown by a kinematic vehicle."""

from __future__ import annotations

import asyncio
import contextlib
import math
import time

import numpy as np
import pytest
from pydantic import ValidationError

from asset_agent.precland.config import ControlConfig, FaultConfig, PrecisionLandingConfig
from asset_agent.precland.control import HOVER
from asset_agent.precland.loop import PrecisionLandingLoop
from asset_agent.precland.pipeline import VehicleState
from asset_agent.precland.transport import IrReceiver, stream_frames
from bench.precland_eval import KinematicVehicle
from sim.camera.server import CameraServer
from sim.clock import SimClock
from sim.ir import IrBeaconSensor


async def wait_for(predicate, within: float = 10.0) -> None:
    """Wait until predicate() holds, failing after `within` wall seconds."""
    deadline = time.monotonic() + within
    while not predicate():
        assert time.monotonic() < deadline, "condition not met in time"
        await asyncio.sleep(0.01)


async def fly(clock, vehicle, setpoint, loop):
    """Step the vehicle at 100 Hz of world time and report its state to the loop."""
    while True:
        await clock.sleep(0.01)
        vehicle.step(0.01, setpoint[0])
        loop.vehicle(
            VehicleState(
                clock.now(),
                (vehicle.n, vehicle.e, -vehicle.up),
                (vehicle.roll, vehicle.pitch, vehicle.yaw),
            )
        )


@pytest.mark.slow
async def test_closed_loop_companion_landing_over_real_sockets():
    clock = SimClock(speed=1.5)
    vehicle = KinematicVehicle(n=0.6, e=-0.4, up=3.0, yaw=0.8)
    setpoint = [HOVER]
    ticks = []

    def on_tick(tick):
        ticks.append(tick)
        if tick.command is not None:
            setpoint[0] = tick.command.setpoint

    loop = PrecisionLandingLoop(
        PrecisionLandingConfig(), on_tick=on_tick, now_fn=clock.now, sleep_fn=clock.sleep
    )
    # the surveyed pad position is 0.5 m off
    loop.pipeline.set_pad_prior((-vehicle.n + 0.4, -vehicle.e - 0.3, vehicle.up))
    camera = CameraServer(vehicle.pose, clock)
    cam_port = await camera.start()
    receiver = IrReceiver()
    ir_port = await receiver.start()
    ir = IrBeaconSensor(vehicle.pose, clock, ("127.0.0.1", ir_port))
    await ir.start()

    async def frames():
        async for frame in stream_frames("127.0.0.1", cam_port):
            loop.frame(frame)

    async def irs():
        async for reading in receiver.readings():
            loop.ir(reading)

    tasks = [
        asyncio.create_task(c)
        for c in (frames(), irs(), fly(clock, vehicle, setpoint, loop), loop.run())
    ]
    try:
        await wait_for(lambda: vehicle.landed, within=80.0)
    finally:
        for t in tasks:
            t.cancel()
        for t in tasks:
            with contextlib.suppress(asyncio.CancelledError):
                await t
        await camera.stop()
        await ir.stop()
        receiver.close()
    assert loop.frames_processed > 20
    states = [t.command.state for t in ticks if t.command is not None]
    assert "approach" in states
    sources = {s for t in ticks if t.target is not None for s in t.target.sources}
    assert {"pattern", "aruco", "ir"} <= sources
    assert math.hypot(vehicle.n, vehicle.e) < 0.05  # seated within the contacts
    assert abs(math.degrees(wrap(vehicle.yaw))) < 5.0  # aligned with the pad's axis


def wrap(a):
    return (a + math.pi) % (2 * math.pi) - math.pi


async def test_run_time_fault_injection_and_landing_target_mode():
    clock = SimClock(speed=1.0)
    pose = (0.3, 0.2, 2.0, 0.0, 0.0, 0.0)
    ticks = []
    cfg = PrecisionLandingConfig(mode="landing_target")
    loop = PrecisionLandingLoop(cfg, on_tick=ticks.append, now_fn=clock.now, sleep_fn=clock.sleep)
    camera = CameraServer(lambda: pose, clock)
    port = await camera.start()

    async def frames():
        async for frame in stream_frames("127.0.0.1", port):
            loop.frame(frame)

    async def states():
        while True:
            loop.vehicle(VehicleState(clock.now(), (pose[0], pose[1], -pose[2]), (0.0, 0.0, 0.0)))
            await clock.sleep(0.02)

    tasks = [asyncio.create_task(c) for c in (frames(), states(), loop.run())]
    try:
        await wait_for(lambda: any(t.landing_target is not None for t in ticks), within=20.0)
        lt = next(t.landing_target for t in ticks if t.landing_target is not None)
        # pad is 0.3 m south and 0.2 m west of the vehicle: behind-left
        assert lt.frame == 12 and lt.angle_x < 0 and lt.angle_y > 0
        assert np.isclose(math.tan(lt.angle_y) * 2.0, 0.3, atol=0.02)
        # every source of the camera fails from now on: after the 1 s hold, no target
        loop.set_fault("pattern", FaultConfig(r_drop=1.0))
        loop.set_fault("aruco", FaultConfig(r_drop=1.0))
        n = len(ticks)
        await wait_for(lambda: len(ticks) > n and ticks[-1].target is None, within=20.0)
        assert ticks[-1].landing_target is None
    finally:
        for t in tasks:
            t.cancel()
        for t in tasks:
            with contextlib.suppress(asyncio.CancelledError):
                await t
        await camera.stop()
    # LANDING_TARGET goes out once per control step, whose rate the config keeps >= 10 Hz
    assert cfg.control.landing_target_rate_hz >= 10
    with pytest.raises(ValidationError):
        ControlConfig(landing_target_rate_hz=5)
