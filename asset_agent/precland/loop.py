"""The one thin loop of precision landing: frames and IR readings in, callbacks out.

Detection runs in a worker thread (never on the event loop), one frame at a time on the newest
frame (older ones are dropped, not queued). The control step runs at the configured rate
(>= 10 Hz, as ArduPilot wants LANDING_TARGET) and calls back with the estimate and either the
LANDING_TARGET fields or the companion-mode command. The agent wires the callbacks to the
autopilot; vehicle states come in through `vehicle()`.
"""

from __future__ import annotations

import asyncio
import logging
import time
from collections.abc import Awaitable, Callable

from asset_agent.precland.config import FaultConfig, PrecisionLandingConfig
from asset_agent.precland.detect import Detections, PadDetector
from asset_agent.precland.pipeline import LandingPipeline, Tick, VehicleState
from asset_agent.precland.transport import Frame, IrReading
from asynckit.tasks import cancel_and_wait

log = logging.getLogger(__name__)


class PrecisionLandingLoop:
    """Runs the detector and the pipeline; emits `Tick`s (and per-frame detections) via callbacks."""

    def __init__(
        self,
        config: PrecisionLandingConfig | None = None,
        on_tick: Callable[[Tick], None] | None = None,
        on_detections: Callable[[float, Detections], None] | None = None,
        now_fn: Callable[[], float] = time.monotonic,
        sleep_fn: Callable[[float], Awaitable[None]] = asyncio.sleep,
        seed: int | None = None,
    ) -> None:
        self.config = config or PrecisionLandingConfig()
        self.pipeline = LandingPipeline(self.config, seed=seed)
        self.detector = PadDetector(self.config.pad, self.config.camera, self.config.detector)
        self.on_tick = on_tick
        self.on_detections = on_detections
        self.now_fn = now_fn  # the clock of the capture timestamps and vehicle states
        self.sleep_fn = sleep_fn  # sleeps in that clock's seconds
        self.frames_processed = 0
        self._frame: Frame | None = None
        self._frame_ready = asyncio.Event()

    # -- inputs (call from the event loop) ---------------------------------------------------

    def frame(self, frame: Frame) -> None:
        """Offer a camera frame; only the newest waiting frame is kept."""
        self._frame = frame
        self._frame_ready.set()

    def ir(self, reading: IrReading) -> None:
        """Offer an IR-beacon reading."""
        self.pipeline.ir(reading.capture_ts, reading.detected, reading.angle_x, reading.angle_y)

    def vehicle(self, state: VehicleState) -> None:
        """Offer the autopilot's position and attitude."""
        self.pipeline.vehicle(state)

    def set_fault(self, source: str, fault: FaultConfig) -> None:
        """Run-time fault injection (a command from the operator or a test)."""
        self.pipeline.set_fault(source, fault, self.now_fn())

    # -- running -----------------------------------------------------------------------------

    async def run(self) -> None:
        """Detect and control until cancelled."""
        detect = asyncio.create_task(self._detect_loop(), name="precland-detect")
        try:
            period = 1.0 / self.config.control.landing_target_rate_hz
            while True:
                tick = self.pipeline.tick(self.now_fn())
                if self.on_tick is not None:
                    try:
                        self.on_tick(tick)
                    except Exception:
                        log.exception("on_tick callback failed")
                await self.sleep_fn(period)
        finally:
            await cancel_and_wait([detect])

    async def _detect_loop(self) -> None:
        while True:
            await self._frame_ready.wait()
            self._frame_ready.clear()
            frame, self._frame = self._frame, None
            if frame is None:
                continue
            state = self.pipeline.state_at(frame.capture_ts)
            roll, pitch = (state.attitude[0], state.attitude[1]) if state else (0.0, 0.0)
            try:
                det = await asyncio.to_thread(self.detector.detect, frame.image, roll, pitch)
            except Exception:
                log.exception("detector failed on frame %d", frame.seq)
                continue
            self.frames_processed += 1
            self.pipeline.detections(frame.capture_ts, det)
            if self.on_detections is not None:
                self.on_detections(frame.capture_ts, det)
