"""The sensors' clock across a restart of their timestamps: a jump back is a new epoch carried on
the agent's time base, not minutes-old data (issue 46)."""

from __future__ import annotations

import pytest

from asset_agent.precland.clock import SensorClock
from asset_agent.precland.config import FusionConfig
from asset_agent.precland.fusion import Fusion
from asset_agent.precland.measure import Measurement


class Wall:
    """A hand-driven monotonic clock."""

    def __init__(self) -> None:
        self.t = 1000.0

    def __call__(self) -> float:
        return self.t


def streamed(clock: SensorClock, wall: Wall, source: str, start: float, n: int, rate: float = 1.0):
    """`n` readings of `source` 0.1 wall seconds apart from sensor time `start`; the mapped times."""
    out = []
    for i in range(n):
        out.append(clock.observe(start + i * 0.1 * rate, source))
        wall.t += 0.1
    return out


@pytest.mark.parametrize("rate", [1.0, 5.0])
def test_timestamps_restarting_near_zero_carry_on_from_the_clocks_now(rate: float) -> None:
    wall = Wall()
    clock = SensorClock(wall=wall)
    before = streamed(clock, wall, "camera", 600.0, 30, rate)  # 10 minutes into the world
    assert before[-1] == pytest.approx(600.0 + 2.9 * rate)
    now = clock.now()
    # the sensor restarted: its timestamps start again near 0
    after = streamed(clock, wall, "camera", 0.5, 30, rate)
    assert clock.epochs == 1
    # the first new reading is taken as captured now, the rest follow it second for second
    assert after[0] == pytest.approx(now, abs=1e-6)
    assert after[-1] - after[0] == pytest.approx(2.9 * rate)
    assert clock.now() >= after[-1] - 1e-9  # the clock goes on, it never went back
    assert clock.rate == pytest.approx(rate, rel=1e-6)


def test_a_new_epochs_readings_are_fresh_for_fusion() -> None:
    wall = Wall()
    clock = SensorClock(wall=wall)
    streamed(clock, wall, "camera", 300.0, 20)
    t = clock.observe(0.2, "camera")  # restarted
    fusion = Fusion(FusionConfig())
    fusion.submit(Measurement("pattern", t, (0.1, 0.0, 5.0), None, 5.0, 0.02))
    target = fusion.step(clock.now())
    assert target is not None and target.kind == "single", target


def test_a_late_reading_of_the_previous_epoch_keeps_its_own_time() -> None:
    wall = Wall()
    clock = SensorClock(wall=wall)
    streamed(clock, wall, "camera", 300.0, 20)  # last stamp 301.9
    restarted = clock.observe(0.1, "camera")
    late = clock.observe(301.95, "camera")  # in flight when the sensor restarted
    assert late == pytest.approx(301.95)  # mapped by the old epoch: no flip back
    assert clock.epochs == 1
    assert clock.observe(0.2, "camera") == pytest.approx(restarted + 0.1)


def test_each_source_follows_its_own_restart() -> None:
    wall = Wall()
    clock = SensorClock(wall=wall)
    for i in range(20):  # camera and IR on one clock
        clock.observe(100.0 + i * 0.1, "ir")
        clock.observe(100.0 + i * 0.1, "camera")
        wall.t += 0.1
    ir_before = clock.observe(102.0, "ir")
    cam = clock.observe(3.0, "camera")  # only the camera rebooted
    ir = clock.observe(102.05, "ir")
    assert clock.epochs == 1
    assert ir == pytest.approx(ir_before + 0.05)  # the IR's time base is untouched
    assert cam == pytest.approx(ir_before, abs=0.06)


def test_a_jump_ahead_of_the_fit_is_a_new_epoch_too() -> None:
    wall = Wall()
    clock = SensorClock(wall=wall)
    streamed(clock, wall, "ir", 10.0, 20)
    now = clock.now()
    t = clock.observe(900.0, "ir")
    assert clock.epochs == 1 and t == pytest.approx(now, abs=1e-6)


def test_delayed_readings_are_not_a_restart() -> None:
    """A frame late by half a second of sensor time (a loaded machine) is the same epoch."""
    wall = Wall()
    clock = SensorClock(wall=wall)
    streamed(clock, wall, "ir", 50.0, 20)
    # the camera's first frame, captured 0.5 s before the clock's now; the next from earlier still
    assert clock.observe(51.5, "camera") == pytest.approx(51.5)
    assert clock.observe(51.1, "camera") == pytest.approx(51.1)
    assert clock.epochs == 0


def test_a_late_first_reading_of_a_new_epoch_does_not_carry_the_source_ahead() -> None:
    """The camera's clock restarted and its first frame came 0.3 s late: the next frames, 0.05 s
    late, set its shift, so the camera stays level with the IR sensor within its own least delay
    (which the agent cannot see) instead of 0.3 s ahead, where the clock's now would have left the
    IR's readings behind: stale for fusion's 0.1 s window."""
    wall = Wall()
    clock = SensorClock(wall=wall)
    for i in range(20):
        clock.observe(200.0 + i * 0.1, "ir")  # on time
        clock.observe(199.95 + i * 0.1, "camera")
        wall.t += 0.1
    truth = 202.0  # the sensors' time now, on the IR's count
    # the camera restarted: its count says 12.0 at the IR's 202.0; its first frame is 0.3 s late
    assert clock.observe(11.7, "camera") == pytest.approx(truth, abs=0.01)
    assert clock.epochs == 1
    for i in range(1, 10):
        wall.t += 0.1
        clock.observe(truth + i * 0.1, "ir")
        t = clock.observe(12.0 + i * 0.1 - 0.05, "camera")  # captured 0.05 s ago
    captured = truth + 0.9 - 0.05
    assert captured <= t < captured + 0.05 + 0.015, t - captured


@pytest.mark.parametrize("rate", [2.0, 5.0])
def test_a_burst_of_readings_after_a_stalled_loop_is_not_a_new_epoch(rate: float) -> None:
    """The agent's loop stalled 1.5 s (a busy machine): the readings queued meanwhile arrive at
    once, each a little after the one before; none is a restart, each keeps its own time."""
    wall = Wall()
    clock = SensorClock(wall=wall)
    streamed(clock, wall, "ir", 100.0, 30, rate)  # last 100 + 2.9 rate, at 0.1 s intervals
    start = 100.0 + 3.0 * rate
    wall.t += 1.5  # stalled
    burst = [clock.observe(start + i * 0.1 * rate, "ir") for i in range(16)]
    assert clock.epochs == 0
    assert burst == pytest.approx([start + i * 0.1 * rate for i in range(16)])


def test_a_restart_whose_new_count_is_near_an_older_epochs_count_is_still_a_new_epoch() -> None:
    """The sensors counted 20 s, jumped to 900 (the world restarted with a later count), then
    restarted from 0: the count near the first epoch's is a new epoch, not that epoch's late
    reading (fresh for fusion, not 20 s old)."""
    wall = Wall()
    clock = SensorClock(wall=wall)
    streamed(clock, wall, "ir", 10.0, 100)  # 10-19.9
    streamed(clock, wall, "ir", 900.0, 30)
    now = clock.now()
    wall.t += 5.0
    t = clock.observe(0.5, "ir")
    assert clock.epochs == 2
    assert t == pytest.approx(now + 5.0, abs=0.05)


def test_readings_queued_behind_a_stalled_loop_do_not_run_the_clock_ahead() -> None:
    """The agent's loop stalled 2.5 s at 5x (longer than the fit's window): the 125 IR readings
    queued meanwhile arrive within 12 ms. A fit through that burst read 1000x and left the clock
    10 s ahead of its sensors (every reading stale for fusion's 0.1 s window); the rate stays."""
    wall = Wall()
    clock = SensorClock(wall=wall)
    ts = 100.0
    for _ in range(100):  # 50 Hz, on time
        clock.observe(ts, "ir")
        ts, wall.t = ts + 0.1, wall.t + 0.02
    queued = []
    for _ in range(125):  # stalled: captured, not yet read
        queued.append(ts)
        ts, wall.t = ts + 0.1, wall.t + 0.02
    for q in queued:
        clock.observe(q, "ir")
        wall.t += 0.0001
    assert clock.rate == pytest.approx(5.0, rel=0.01)
    for _ in range(20):  # on time again: each reading is the clock's now as it arrives
        clock.observe(ts, "ir")
        assert clock.now() == pytest.approx(ts, abs=0.01)
        ts, wall.t = ts + 0.1, wall.t + 0.02
    assert clock.epochs == 0


def test_a_camera_first_frame_slow_to_render_is_not_a_new_epoch() -> None:
    """At 5x, the camera's first frame of a landing comes 1.5 wall seconds late (7.5 sensor
    seconds): the same clock as the IR's, late, not a restarted camera taken as captured now."""
    wall = Wall()
    clock = SensorClock(wall=wall)
    streamed(clock, wall, "ir", 100.0, 30, 5.0)
    now = clock.now()
    assert clock.observe(now - 7.5, "camera") == pytest.approx(now - 7.5)
    assert clock.epochs == 0
