"""The precision-landing pipeline without I/O: detections and IR readings in, through fault
injection, fusion and the Kalman filter, to LANDING_TARGET fields or velocity setpoints out.

`PrecisionLandingLoop` wraps it with threads and timers; the evaluation drives it directly.
Vision readings are taken at their capture time; before fusion they are moved to "now" by the
vehicle's own displacement since then (from the autopilot's positions), so a late frame does not
drag the estimate back.
"""

from __future__ import annotations

import bisect
import logging
from collections import deque
from dataclasses import dataclass

import numpy as np

from asset_agent.precland.config import FaultConfig, PrecisionLandingConfig
from asset_agent.precland.control import LandingTarget, landing_target
from asset_agent.precland.detect import Detections
from asset_agent.precland.faults import FaultInjector
from asset_agent.precland.fusion import FusedTarget, Fusion
from asset_agent.precland.kalman import Estimate, TargetKalman
from asset_agent.precland.measure import Attitude, Measurement, from_element, from_ir
from asset_agent.precland.sequence import Command, LandingSequence

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class VehicleState:
    """The autopilot's view at time t: local NED position (m), attitude (rad) and, when known,
    local NED velocity (m/s) and its GNSS fix type (GPS_RAW_INT fix_type: 6 RTK fixed, 5 RTK
    float, 3 a plain 3D fix)."""

    t: float
    position_ned: tuple[float, float, float]
    attitude: Attitude
    velocity_ned: tuple[float, float, float] | None = None
    gnss_fix: int | None = None


@dataclass(frozen=True)
class Tick:
    """The outcome of one control step."""

    t: float
    target: FusedTarget | None
    estimate: Estimate
    command: Command | None
    landing_target: LandingTarget | None


class LandingPipeline:
    """Fault injection → fusion → Kalman → control, fed by detections, IR and vehicle states."""

    HISTORY_S = 2.0

    def __init__(
        self, config: PrecisionLandingConfig | None = None, seed: int | None = None
    ) -> None:
        self.config = config or PrecisionLandingConfig()
        self.faults = FaultInjector(self.config.faults, seed=seed)
        self.fusion = Fusion(self.config.fusion)
        self.kalman = TargetKalman(self.config.kalman)
        self.sequence = LandingSequence(
            self.config.control, self.config.retry, self.config.search, self.config.camera
        )
        # recent vehicle states, each with its odometry: the displacement the filter was
        # predicted with, summed (where the vehicle is "now" against where a late frame saw
        # the pad from)
        self._track: deque[tuple[VehicleState, np.ndarray]] = deque()
        self._detection_sent_t: float | None = None

    # -- inputs ------------------------------------------------------------------------------

    def set_pad_prior(self, rel_ned, sigma_m: float | None = None) -> None:
        """Start the filter from the surveyed pad position minus the vehicle's GNSS position."""
        self.kalman.reset(rel_ned, sigma_m)

    def set_fault(self, source: str, fault: FaultConfig, now: float) -> None:
        """Run-time fault injection command for one source."""
        self.faults.set(source, fault, now)

    def vehicle(self, state: VehicleState) -> None:
        """A new autopilot state: predicts the filter with the vehicle's displacement."""
        odometry = np.zeros(3)
        if self._track:
            prev, prev_odometry = self._track[-1]
            if state.t < prev.t:
                log.warning("vehicle state out of order dropped")
                return
            delta, by_velocity = self._displacement(prev, state)
            self.kalman.predict(delta, state.t - prev.t, by_velocity, state.gnss_fix)
            odometry = prev_odometry + delta
        self._track.append((state, odometry))
        while state.t - self._track[0][0].t > self.HISTORY_S:
            self._track.popleft()

    def _displacement(self, prev: VehicleState, state: VehicleState) -> tuple[np.ndarray, bool]:
        """How far the vehicle moved between two states, and whether horizontally from its
        velocity (trapezoidal) rather than its position delta.

        The velocity only once the filter has had a measurement: from then on it learns the
        velocity's slow bias, which unchecked would drift the estimate without bound (the GNSS
        error stays bounded). The height always from the positions: the autopilot's is
        baro-aided, and nothing else may measure it (IR alone does not).
        """
        delta = np.subtract(state.position_ned, prev.position_ned)
        if (
            self.config.kalman.motion != "velocity"
            or self.kalman.updates == 0
            or prev.velocity_ned is None
            or state.velocity_ned is None
        ):
            return delta, False
        mean_v = np.add(prev.velocity_ned, state.velocity_ned) / 2
        delta[:2] = mean_v[:2] * (state.t - prev.t)
        return delta, True

    def _index_at(self, t: float) -> int | None:
        if not self._track:
            return None
        times = [s.t for s, _ in self._track]
        i = bisect.bisect_left(times, t)
        cands = [j for j in (i - 1, i) if 0 <= j < len(times)]
        return min(cands, key=lambda j: abs(times[j] - t))

    def state_at(self, t: float) -> VehicleState | None:
        """The recorded vehicle state nearest to time t."""
        i = self._index_at(t)
        return None if i is None else self._track[i][0]

    def detections(
        self, t: float, det: Detections, attitude: Attitude | None = None
    ) -> list[Measurement]:
        """A frame's detections (captured at t) into fusion; returns the admitted measurements."""
        state = self.state_at(t)
        if attitude is None:
            if state is None:
                return []
            attitude = state.attitude
        out = []
        for element in (det.pattern, det.aruco):
            if element is None:
                continue
            m = from_element(element, t, attitude, self.config.camera)
            out += self._admit(m)
        return out

    def ir(self, t: float, detected: bool, angle_x: float, angle_y: float) -> list[Measurement]:
        """An IR reading into fusion (scaled by the filter's height); returns what was admitted."""
        state = self.state_at(t)
        if not detected or state is None or not self.kalman.initialised:
            return []
        # the camera is never lower than its seat on the pad: a height estimate below that (a
        # surveyed pad altitude off by decimetres) would shrink or drop the last readings
        height = max(self.kalman.estimate().rel_ned[2], self.config.control.touchdown_height)
        m = from_ir(
            angle_x,
            angle_y,
            t,
            state.attitude,
            height,
            self.config.camera,
            self.config.pad,
            self.kalman.heading,
            self.config.kalman.vision_sigma(height),  # IR reports no uncertainty: the model's
        )
        return self._admit(m)

    def _admit(self, m: Measurement) -> list[Measurement]:
        if not self.faults.admit(m.source, m.t, m.height):
            return []
        self.fusion.submit(m)
        return [m]

    @property
    def path(self) -> str:
        """Which way this landing went (companion mode: the sequence's; see `LandingSequence.path`)."""
        return self.sequence.path

    # -- one control step ----------------------------------------------------------------------

    def tick(self, now: float) -> Tick:
        """Fuse, update the filter, and compute the command for time `now`."""
        target = self.fusion.step(now)
        if target is not None and target.kind != "held":
            rel = np.asarray(target.rel_ned) - self._moved_since(target.t)
            # the detector's sigma where it says more than the vision model, else the model's:
            # trusted below the model, it let the estimate follow each frame's error in gusts
            # (fused-wind5, 5 seeds: 2.6 / 6.1 cm against 1.4 / 3.3)
            sigma = max(target.sigma_m or 0.0, self.kalman.config.vision_sigma(float(rel[2])))
            self.kalman.update(rel, sigma, heading=target.heading, t=target.t)
        est = self.kalman.estimate()
        state = self._track[-1][0] if self._track else None
        cmd = lt = None
        if state is not None and self.kalman.initialised:
            if self.config.mode == "companion":
                fresh = target is not None and target.kind != "held"
                cmd = self.sequence.follow(now, target is not None, est, state, fresh)
            elif target is not None and self.config.steering == "autopilot":
                lt = self._detection_target(target)
            elif target is not None:
                rel = self._predicted(est.rel_ned, state, now)
                lt = landing_target(rel, state.attitude, now, 2 * self.config.pad.pattern_radius)
            if lt is not None and not lt.below:  # level with the camera: the autopilot refuses it
                lt = None
        return Tick(now, target, est, cmd, lt)

    @staticmethod
    def _predicted(rel_ned, state: VehicleState, now: float) -> np.ndarray:
        """The estimate (relative to the vehicle at its last reported state) carried to `now` by
        the vehicle's reported velocity: the autopilot adds the LANDING_TARGET to where it is when
        the message arrives, so a vector as old as the state would lead a moving vehicle by its
        velocity times that age (at 25 Hz of states, up to 40 ms; in a simulation run N times
        faster than the wall clock, N times more world time), and a loop that leads oscillates."""
        rel = np.asarray(rel_ned, dtype=np.float64)
        if state.velocity_ned is None:
            return rel
        age = min(max(now - state.t, 0.0), 0.5)
        return rel - np.asarray(state.velocity_ned) * age

    def _detection_target(self, target: FusedTarget) -> LandingTarget | None:
        """steering "autopilot": each new measurement once, as the camera saw it — in the body
        frame of its capture time, unfiltered — for the autopilot's own estimator (ArduPilot's
        PLND takes it PLND_LAG late, with its attitude of then). Held values are not resent."""
        if target.kind == "held" or target.t == self._detection_sent_t:
            return None
        state = self.state_at(target.t)
        if state is None:
            return None
        self._detection_sent_t = target.t
        size = 2 * self.config.pad.pattern_radius
        return landing_target(target.rel_ned, state.attitude, target.t, size)

    def _moved_since(self, t: float) -> np.ndarray:
        i = self._index_at(t)
        if i is None:
            return np.zeros(3)
        return self._track[-1][1] - self._track[i][1]
