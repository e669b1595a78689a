"""The simulated IR-beacon sensor: angles, range and field of view, over real UDP."""

from __future__ import annotations

import asyncio
import math
import time

import numpy as np

from asset_agent.precland.transport import IrReceiver, parse_ir
from sim.clock import SimClock
from sim.ir import DATAGRAM, IrBeaconSensor, IrSensorConfig, encode_reading, ir_reading


async def wait_for(predicate, within: float = 10.0) -> None:
    """Wait until predicate() holds, failing after `within` wall seconds."""
    deadline = time.monotonic() + within
    while not predicate():
        assert time.monotonic() < deadline, "condition not met in time"
        await asyncio.sleep(0.005)


def test_angles_range_and_field_of_view():
    cfg = IrSensorConfig(noise_rad=0.0)
    ok, ax, ay = ir_reading((0.5, -0.3, 4.0, 0.0, 0.0, 0.0), cfg)
    # beacon is 0.5 m behind (tail = +y in the image) and 0.3 m to the right
    assert ok and math.isclose(ax, math.atan2(0.3, 4.0)) and math.isclose(ay, math.atan2(0.5, 4.0))
    # yawed 90° right (nose east): the beacon to the south is now on the right
    ok, ax, ay = ir_reading((0.5, 0.0, 4.0, 0.0, 0.0, math.pi / 2), cfg)
    assert ok and math.isclose(ax, math.atan2(0.5, 4.0)) and abs(ay) < 1e-9
    assert not ir_reading((0.0, 0.0, 20.0, 0, 0, 0), cfg)[0]  # beyond range
    assert not ir_reading((5.0, 0.0, 2.0, 0, 0, 0), cfg)[0]  # outside the field of view
    noisy = [
        ir_reading((0, 0, 3, 0, 0, 0), IrSensorConfig(), np.random.default_rng(i))[1]
        for i in range(200)
    ]
    assert 0.001 < float(np.std(noisy)) < 0.004


def test_datagram_format_agrees_with_the_agent():
    assert DATAGRAM.size == 28
    r = parse_ir(encode_reading(3, 1.5, True, 0.25, -0.125))
    assert r is not None and (r.seq, r.capture_ts, r.detected, r.angle_x, r.angle_y) == (
        3,
        1.5,
        True,
        0.25,
        -0.125,
    )
    assert parse_ir(b"garbage") is None


async def test_readings_stream_at_50hz_over_udp():
    clock = SimClock(speed=4.0)
    receiver = IrReceiver()
    port = await receiver.start()
    sensor = IrBeaconSensor(lambda: (0.2, 0.1, 3.0, 0, 0, 0), clock, ("127.0.0.1", port))
    await sensor.start()
    t0 = clock.now()
    try:
        readings = []
        async for r in receiver.readings():
            readings.append(r)
            if len(readings) == 40:
                break
    finally:
        await sensor.stop()
        receiver.close()
    assert all(r.detected for r in readings)
    gaps = np.diff([r.capture_ts for r in readings])
    # 50 Hz on the world clock: the typical gap is the period. A starved process wakes late
    # now and then (the sensor then catches up with its schedule or skips a reading, as a real
    # one would), so the median is checked, not the whole span.
    assert 0.02 * 0.8 <= float(np.median(gaps)) <= 0.02 * 1.5
    assert readings[0].capture_ts >= t0
    assert abs(np.mean([r.angle_x for r in readings]) - math.atan2(-0.1, 3.0)) < 0.002
