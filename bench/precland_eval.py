"""`python bench/precland_eval.py`: closed-loop precision landings, in process, per scenario.

Each trial: render → detect → fault injection → fusion → Kalman → control → vehicle, stepped at
100 Hz of simulated time (camera 33 Hz, IR 50 Hz, control 33 Hz), as fast as the CPU allows.
The vehicle is `KinematicVehicle`, a small model of our own (the shared multirotor dynamics were
not committed when this was written): first-order velocity tracking with acceleration and speed
limits, attitude from the acceleration it demands plus the wind it leans into (max 15°), the
part of the wind its velocity loop has not yet integrated away (gusts) leaking into ground speed,
and a seat at camera height 0.25 m.
Start 10 m (or 6 m) high and 2 m off; the surveyed pad position carries a setup error of up to
1 m on a plain fix, 2 cm with RTK (`RTK_SURVEY_SCALE`); the positions the agent sees carry the GNSS error of the scenario's fix type (RTK fixed by
default, RTK float or a plain 3D fix: bench/precland_gnss.py), reported to the agent as
GPS_RAW_INT's fix_type would be, and the velocities it sees (the autopilot EKF's, GNSS Doppler +
IMU) carry `EkfVelocityError`. A pad not in view is searched for, then the fallback (RTK fixed:
land on GNSS; otherwise climb and hold: the trial ends "aborted-climb", not landed).
Two landing paths (`--path`, default both): the agent steers the descent (the above), or the
simulated autopilot (sim.vehicle.copter, ArduPilot 4 habits) flies LAND with ArduPilot's precision
landing (sim/vehicle/plnd.py) fed our detections by LANDING_TARGET (`run_autopilot_trial`), rows
marked "[autopilot PLND]"; its EKF position drifts with the same GNSS error (the same model and
draws per seed, `CopterGnss`) and its surveyed pad carries the same error. `--camera-hz` sets the camera's frame rate (the control loop stays at
33 Hz). Prints a table (scenario, mean / max landing error in cm, heading error, mean landing
time), one row as each scenario finishes, and, with --json, one JSON object last.
"""

from __future__ import annotations

import argparse
import json
import math
import statistics
import sys
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

import numpy as np

if __name__ == "__main__":  # run as a script from a checkout
    sys.path.insert(0, str(__import__("pathlib").Path(__file__).resolve().parents[1]))

from asset_agent.autopilot.setpoints import VELOCITY_ONLY
from asset_agent.precland.config import (
    DetectorConfig,
    FaultConfig,
    PrecisionLandingConfig,
    RetryConfig,
)
from asset_agent.precland.control import VelocitySetpoint
from asset_agent.precland.detect import PadDetector
from asset_agent.precland.geometry import wrap_angle
from asset_agent.precland.guard import LossGuard
from asset_agent.precland.pipeline import LandingPipeline, VehicleState
from bench.precland_gnss import MODELS, CopterGnss, GnssError, GnssModel
from bench.precland_report import Trace, write_report
from bench.precland_wind import trial_weather
from sim.camera.render import CameraEffects, PadRenderer
from sim.ir import IrSensorConfig, ir_reading

G = 9.81
SEAT_HEIGHT = 0.25  # camera height above the pad when the vehicle sits on it


@dataclass
class KinematicVehicle:
    """A multirotor as a velocity-tracking point mass with yaw, tilt from acceleration and wind."""

    n: float
    e: float
    up: float
    yaw: float
    vel: np.ndarray = field(default_factory=lambda: np.zeros(3))  # NED m/s
    roll: float = 0.0
    pitch: float = 0.0
    tau: float = 0.35
    max_accel: float = 3.0
    max_tilt: float = math.radians(15)
    wind_leak: float = 0.1
    wind_tau: float = 2.0
    wind_seen: np.ndarray = field(default_factory=lambda: np.zeros(2))
    landed: bool = False
    seed: int | None = None  # unused: the wind it gets is the 20 ft wind, no shear or turbulence

    def pose(self) -> tuple[float, float, float, float, float, float]:
        """(north, east, up, roll, pitch, yaw) relative to the pad centre."""
        return (self.n, self.e, self.up, self.roll, self.pitch, self.yaw)

    def step(self, dt: float, sp: VelocitySetpoint, wind_ne=(0.0, 0.0)) -> None:
        """Advance dt seconds tracking the setpoint, pushed by the wind."""
        if self.landed:
            return
        target = np.array([sp.vn, sp.ve, sp.vd])
        if sp.land:
            target = np.array([0.0, 0.0, 0.3])
        acc = (target - self.vel) / max(self.tau, dt)
        norm = float(np.linalg.norm(acc[:2]))
        if norm > self.max_accel:
            acc[:2] *= self.max_accel / norm
        self.vel = self.vel + acc * dt
        self.yaw = wrap_angle(self.yaw + sp.yaw_rate * dt)
        wn, we = wind_ne
        # the autopilot's velocity loop integrates the steady wind away (time constant wind_tau);
        # what it has not absorbed yet (gusts) leaks into the ground speed
        self.wind_seen += (np.array([wn, we]) - self.wind_seen) * min(1.0, dt / self.wind_tau)
        leak_n, leak_e = self.wind_leak * (np.array([wn, we]) - self.wind_seen)
        self.n += (self.vel[0] + leak_n) * dt
        self.e += (self.vel[1] + leak_e) * dt
        self.up -= self.vel[2] * dt
        # lean into the demanded acceleration and the wind (drag ~ 0.015 g per m/s of wind)
        an, ae = acc[0] + 0.15 * wn, acc[1] + 0.15 * we
        c, s = math.cos(self.yaw), math.sin(self.yaw)
        fwd, right = c * an + s * ae, -s * an + c * ae
        self.pitch = max(-self.max_tilt, min(self.max_tilt, -math.atan2(fwd, G)))
        self.roll = max(-self.max_tilt, min(self.max_tilt, math.atan2(right, G)))
        if self.up <= SEAT_HEIGHT:
            self.up, self.landed = SEAT_HEIGHT, True
            self.vel = np.zeros(3)
            self.roll = self.pitch = 0.0


class SharedVehicle:
    """The world's multirotor (sim.vehicle.dynamics.Dynamics) behind the evaluation's vehicle
    interface: velocity setpoints in, pose out; the yaw rate becomes a yaw target ahead of the
    current yaw; the camera sits SEAT_HEIGHT above the vehicle's ground contact. It flies in the
    air of its own `sim.wind.Airflow` (shear and Dryden turbulence, seeded), as the world's copter."""

    YAW_LEAD_S = 0.5

    def __init__(self, n: float, e: float, up: float, yaw: float, seed: int | None = None) -> None:
        from sim.vehicle.dynamics import Dynamics, DynamicsState
        from sim.wind import Airflow

        start = DynamicsState(position=(n, e, -(up - SEAT_HEIGHT)), yaw=yaw, landed=False)
        self.dyn = Dynamics(state=start)
        self.dyn.motors_on = True
        self.airflow = Airflow(seed=seed)
        self.landed = False

    @property
    def n(self) -> float:
        """North of the pad centre (m)."""
        return self.dyn.state.position[0]

    @property
    def e(self) -> float:
        """East of the pad centre (m)."""
        return self.dyn.state.position[1]

    @property
    def yaw(self) -> float:
        """Yaw (rad)."""
        return self.dyn.state.yaw

    def pose(self) -> tuple[float, float, float, float, float, float]:
        """(north, east, camera height, roll, pitch, yaw) relative to the pad centre."""
        st = self.dyn.state
        return (
            st.position[0],
            st.position[1],
            SEAT_HEIGHT - st.position[2],
            st.roll,
            st.pitch,
            st.yaw,
        )

    def step(self, dt: float, sp: VelocitySetpoint, wind_ne=(0.0, 0.0)) -> None:
        """Advance dt seconds tracking the setpoint in the wind `wind_ne` 20 ft above the ground."""
        if self.landed:
            return
        vel = (0.0, 0.0, 0.3) if sp.land else (sp.vn, sp.ve, sp.vd)
        self.dyn.set_velocity_target(vel, yaw=self.dyn.state.yaw + sp.yaw_rate * self.YAW_LEAD_S)
        st = self.dyn.state
        air = self.airflow.step(dt, wind_ne, st.altitude, (st.velocity[0], st.velocity[1]))
        self.landed = self.dyn.step(dt, (air[0], air[1])).landed


VEHICLES = {"shared": SharedVehicle, "kinematic": KinematicVehicle}


def gauss_markov(
    x: np.ndarray, sigma: float, tau: float, dt: float, rng: np.random.Generator, scale: Any = 1.0
) -> np.ndarray:
    """One step of a first-order Gauss-Markov process of stationary sigma and time constant tau
    (the driving noise multiplied by `scale`, e.g. a smaller vertical part)."""
    decay = math.exp(-dt / tau)
    return x * decay + rng.normal(0, sigma * math.sqrt(1 - decay**2), len(x)) * scale


class EkfVelocityError:
    """The error of the autopilot EKF's velocity (LOCAL_POSITION_NED vx, vy, vz), per axis: a
    noise of 0.05 m/s, new at each 5 Hz GNSS epoch, plus a bias of 0.03 m/s wandering over 30 s.

    Why these: the EKF's velocity follows the receiver's Doppler velocity, which u-blox M8/M9/F9
    class receivers specify at 0.05 m/s and deliver at 5-10 Hz; the EKF smooths it with the IMU
    between epochs, which changes how it looks but not how it adds up: integrated it is a random
    walk of 0.05 x sqrt(0.2 s) = 0.022 m/sqrt(s), modelled as a Gauss-Markov noise of 0.05 m/s
    and 0.1 s (same low-frequency content). Slow errors (IMU bias and tilt not yet corrected, the
    EKF pulled by GNSS position innovations) are the bias: at 0.03 m/s over 30 s it exceeds the
    part of the GNSS model's own drift that stays correlated over tens of seconds (the mean rate
    over 30 s of a 0.5 m / 120 s Gauss-Markov error is ~0.012 m/s), so the velocity is not made
    cleaner than the positions it is compared with.
    """

    NOISE_SIGMA, NOISE_TAU = 0.05, 0.1
    BIAS_SIGMA, BIAS_TAU = 0.03, 30.0

    def __init__(self, rng: np.random.Generator) -> None:
        self.rng = rng
        self.noise = rng.normal(0, self.NOISE_SIGMA, 3)
        self.bias = rng.normal(0, self.BIAS_SIGMA, 3)

    def step(self, dt: float) -> np.ndarray:
        """Advance dt seconds; the current error (m/s, NED)."""
        self.noise = gauss_markov(self.noise, self.NOISE_SIGMA, self.NOISE_TAU, dt, self.rng)
        self.bias = gauss_markov(self.bias, self.BIAS_SIGMA, self.BIAS_TAU, dt, self.rng)
        return self.noise + self.bias


@dataclass(frozen=True)
class Scenario:
    """One evaluation scenario: the sensors used, their faults, the approach, the start."""

    name: str
    sensors: tuple[str, ...]  # "marker" (pattern + ArUco), "pattern" (alone) and/or "ir"
    faults: dict[str, FaultConfig] = field(default_factory=dict)
    cautious: bool = False
    start_height: float = 10.0
    wind: float = 2.0  # mean wind 20 ft above the ground, m/s (bench/precland_wind.py)
    gust: float = 1.0  # the peak of one discrete 1 - cosine gust on top, m/s
    gnss: str = "rtk_fixed"  # the fix type of the autopilot's GNSS (bench/precland_gnss.py)
    survey_error_m: float | None = None  # the surveyed pad this far off (default: up to 1 m)
    start_over_survey: bool = False  # start over the surveyed pad (as RTL returns), not 2 m off

    @property
    def sources(self) -> set[str]:
        """The fusion's sources the sensors give."""
        out = {"ir"} if "ir" in self.sensors else set()
        if "marker" in self.sensors:
            out |= {"pattern", "aruco"}
        if "pattern" in self.sensors:
            out.add("pattern")
        return out


def _marker(f: FaultConfig) -> dict[str, FaultConfig]:
    return {"pattern": f, "aruco": f}


RANDOM = FaultConfig(r_drop=0.5)
BELOW3 = FaultConfig(fail_below_m=3.0)
ABOVE3 = FaultConfig(fail_above_m=3.0)


def _single_source_failures() -> list[Scenario]:
    """Issue 19 item 1: each source alone, failing below or above 3 m, cautious retries; and the
    marker failing below 3 m on an RTK float and a plain 3D fix."""
    out = []
    for source in ("marker", "pattern", "ir"):
        for fault, side in ((BELOW3, "below3"), (ABOVE3, "above3")):
            faults = _marker(fault) if source == "marker" else {source: fault}
            out.append(Scenario(f"{source}-{side}-cautious", (source,), faults, cautious=True))
    for gnss in ("rtk_float", "3d"):
        name = f"marker-below3-cautious-{gnss.replace('_', '-')}"
        out.append(Scenario(name, ("marker",), _marker(BELOW3), cautious=True, gnss=gnss))
    return out


SCENARIOS: dict[str, Scenario] = {
    s.name: s
    for s in (
        Scenario("none", ()),
        Scenario("ir", ("ir",)),
        Scenario("marker", ("marker",)),
        Scenario("fused", ("marker", "ir")),
        Scenario("marker-random", ("marker",), _marker(RANDOM)),
        Scenario("marker-below3", ("marker",), _marker(BELOW3)),
        Scenario("marker-above3", ("marker",), _marker(ABOVE3)),
        *_single_source_failures(),
        # the search (issue 19 item 2): the pad 4 m from where it was surveyed, out of the
        # camera's view from 5 m; and the fallback when it is never seen (IR failing above 3 m)
        *(
            Scenario(  # cautious, as the agent's configuration is by default
                name,
                sensors,
                cautious=True,
                start_height=5.0,
                survey_error_m=4.0,
                start_over_survey=True,
            )
            for name, sensors in (("search-4m", ("marker", "ir")), ("search-4m-ir", ("ir",)))
        ),
        Scenario(
            "fallback-ir-above3-float", ("ir",), {"ir": ABOVE3}, cautious=True, gnss="rtk_float"
        ),
        Scenario("ir-random", ("ir",), {"ir": RANDOM}),
        Scenario("fused-random", ("marker", "ir"), {**_marker(RANDOM), "ir": RANDOM}),
        Scenario("fused-marker-below3", ("marker", "ir"), _marker(BELOW3)),
        Scenario("fused-marker-above3", ("marker", "ir"), _marker(ABOVE3)),
        Scenario("fused-ir-below3", ("marker", "ir"), {"ir": BELOW3}),
        Scenario("fused-ir-above3", ("marker", "ir"), {"ir": ABOVE3}),
        Scenario(
            "fused-ir-below3-marker-above3", ("marker", "ir"), {"ir": BELOW3, **_marker(ABOVE3)}
        ),
        Scenario("fused-6m", ("marker", "ir"), start_height=6.0),
        # wind (issue 19 item 4, bench/precland_wind.py): W20 with a gust of half of it on top
        *(Scenario(f"fused-wind{w}", ("marker", "ir"), wind=w, gust=w / 2) for w in (0, 5, 8, 12)),
        # the thesis's field trial: fused, "windy" (6 m/s, a 3 m/s gust), no RTK; the paper's
        # field camera (§4): the pattern seen only below ~4 m and half its frames rejected, the
        # ArUco's rate cut by flare and saturation
        Scenario(
            "thesis-field",
            ("marker", "ir"),
            {
                "pattern": FaultConfig(fail_above_m=4.0, r_drop=0.5),
                "aruco": FaultConfig(r_drop=0.5),
            },
            wind=6.0,
            gust=3.0,
            gnss="3d",  # the thesis's field UAV flew without RTK
        ),
    )
}
PER_SOURCE = "per-source"
PUBLISHED = {  # thesis field results (cm, mean / max) where a scenario matches one
    "none": "67.2 / 180",
    "ir": "5.8 / 13.9",
    "marker": "8.5 / 11.6",
    "marker-random": "11.1 / 16.5",
    "marker-below3": "39.3 / 62.9",
    "marker-below3-cautious": "14.4 / 24.1",
    "fused": "13.6 / 24.6",
    "fused-random": "29.4 / 46.1",
    "fused-ir-below3-marker-above3": "14.7 / 20.6",
    "thesis-field": "13.6 / 24.6",
}


CAMERA_HZ = 100 / 3  # a frame every third 10 ms step, with each control step
# The surveyed pad's error in the frame the UAV navigates in. On a plain fix the pad was surveyed
# independently of the UAV's GNSS: up to 1 m off (0.2 m in height). With RTK (fixed or float) the
# UAV's positions are relative to the base's receiver, and the pad is a lever arm measured from
# the base's antenna at installation: up to 2 cm (2 cm in height), whatever the base's own
# absolute error — the same draws scaled by this.
RTK_SURVEY_SCALE = 0.02
RETURNED_M = 0.5  # RTL's return is over this close to home (sim.vehicle.guidance)


@dataclass(frozen=True)
class Trial:
    """One landing: horizontal error (m), heading error (deg), duration (s), whether it landed,
    where it touched down (north, east of the pad centre, m), and the landing's path (the
    agent's `LandingSequence.path`; "autopilot" for the autopilot's own)."""

    error_m: float
    heading_deg: float
    time_s: float
    landed: bool
    touchdown: tuple[float, float] = (0.0, 0.0)
    path: str = "precision"


def _config(
    sc: Scenario, sources: set[str], motion: str | None, **update: Any
) -> PrecisionLandingConfig:
    base = PrecisionLandingConfig()
    return base.model_copy(
        update={
            "faults": sc.faults,
            "retry": RetryConfig(cautious=sc.cautious),
            "fusion": base.fusion.model_copy(
                update={"sources": {k: v for k, v in base.fusion.sources.items() if k in sources}}
            ),
            "kalman": base.kalman.model_copy(update={"motion": motion or base.kalman.motion}),
            **update,
        }
    )


def _survey_and_start(
    sc: Scenario, rng: np.random.Generator, a0: float, gnss_model: GnssModel
) -> tuple[np.ndarray, tuple[float, float]]:
    """The surveyed pad (NED of the true pad, m) and the start (north, east), drawn from the
    trial's generator after its start direction `a0` and yaw: up to 1 m off (0.2 m in height) on a
    plain fix, those draws scaled by `RTK_SURVEY_SCALE` with RTK, or `sc.survey_error_m` off in
    the drawn direction; the start 2 m off in direction `a0`, or over the survey. Both landing
    paths draw them so, so that a seed is the same world on either."""
    survey = rng.uniform(0, 1.0) * np.array([math.cos(a := rng.uniform(0, 6.3)), math.sin(a), 0.0])
    survey[2] = rng.normal(0, 0.2)
    if gnss_model.fix != "3d":  # with RTK the pad is known in the base's own frame
        survey *= RTK_SURVEY_SCALE
    if sc.survey_error_m is not None:  # the surveyed pad this far off, in the drawn direction
        survey[:2] *= sc.survey_error_m / max(float(np.hypot(*survey[:2])), 1e-9)
    start = (2.0 * math.cos(a0), 2.0 * math.sin(a0))
    if sc.start_over_survey:
        start = (float(survey[0]), float(survey[1]))
    return survey, start


def run_trial(
    sc: Scenario,
    seed: int,
    max_time: float = 150.0,
    vehicle_model: str = "shared",
    motion: Literal["position", "velocity"] | None = None,
    camera_hz: float = CAMERA_HZ,
    trace: Trace | None = None,
    gnss_fix: str | None = None,
) -> Trial:
    """Fly one closed-loop landing of scenario `sc` with the chosen vehicle model (and what
    predicts the agent's filter, when not its configured default), the camera at `camera_hz`
    (the control loop stays at 33 Hz), the GNSS at the scenario's fix type unless `gnss_fix`
    names another. Ends at touchdown, or when an aborted landing holds its safe height."""
    rng = np.random.default_rng(seed)
    a0, yaw0 = rng.uniform(0, 2 * math.pi), rng.uniform(-math.pi, math.pi)
    sources = sc.sources
    camera = bool(sources & {"pattern", "aruco"})
    cfg = _config(sc, sources, motion)
    pipeline = LandingPipeline(cfg, seed=seed)
    renderer = PadRenderer(effects=CameraEffects(noise_sigma=2.0), seed=seed) if camera else None
    det_cfg = DetectorConfig(use_frame=True, use_aruco="aruco" in sources)
    detector = PadDetector(cfg.pad, cfg.camera, det_cfg) if camera else None
    ir_cfg = IrSensorConfig()
    gnss_model = MODELS[gnss_fix or sc.gnss]
    survey, start = _survey_and_start(sc, rng, a0, gnss_model)
    vehicle = VEHICLES[vehicle_model](*start, sc.start_height, yaw0, seed=seed)
    # its own generator, so that the other random streams do not depend on the model
    gnss_error = GnssError(gnss_model, np.random.default_rng((seed, 2)))
    gnss = gnss_error.value
    dt, t, sp = 0.01, 0.0, VelocitySetpoint(0.0, 0.0, 0.0)
    weather = trial_weather(sc.wind, sc.gust, seed)  # the world's wind model (precland_wind.py)

    # its own generator, so that the other random streams are the same as without it
    vel_error = EkfVelocityError(np.random.default_rng((seed, 1)))

    def true_position() -> np.ndarray:
        return np.array([vehicle.n, vehicle.e, -vehicle.pose()[2]])

    def gnss_position() -> tuple[float, float, float]:
        p = true_position() + gnss
        return (float(p[0]), float(p[1]), float(p[2]))

    def holding() -> bool:  # an aborted landing at its safe height: the trial is over
        return pipeline.sequence.holding_safe

    # prior: surveyed pad position (true + setup error) minus the GNSS position
    pipeline.set_pad_prior(
        survey - np.array(gnss_position()) + np.array([0, 0, -SEAT_HEIGHT * 0]), 1.0
    )
    k, next_frame = 0, dt  # the first frame with the first control step
    while t < max_time and not vehicle.landed and not holding():
        before = true_position()
        vehicle.step(dt, sp, weather.flow_ne(t))
        # the ground velocity over the step (wind leak included), as the EKF would estimate it
        vel = (true_position() - before) / dt + vel_error.step(dt)
        gnss = gnss_error.step(dt)
        t += dt
        pose = vehicle.pose()
        pipeline.vehicle(
            VehicleState(
                t,
                gnss_position(),
                (pose[3], pose[4], pose[5]),
                (float(vel[0]), float(vel[1]), float(vel[2])),
                gnss_model.fix_type,
            )
        )
        if "ir" in sc.sensors and k % 2 == 0:
            ok, ax, ay = ir_reading(pose, ir_cfg, rng)
            pipeline.ir(t, ok, ax, ay)
        if renderer is not None and detector is not None and t >= next_frame - 1e-9:
            next_frame += 1.0 / camera_hz
            pipeline.detections(t, detector.detect(renderer.render(pose), pose[3], pose[4]))
        if k % 3 == 0:
            tick = pipeline.tick(t)
            if tick.command is not None:
                sp = tick.command.setpoint
        if trace is not None:  # the report's error-vs-time plot (precland_report.py)
            est = pipeline.kalman.estimate().rel_ned if pipeline.kalman.initialised else None
            trace.record(t, (vehicle.n, vehicle.e), pose[2], None if est is None else est[:2])
        k += 1
    return Trial(
        math.hypot(vehicle.n, vehicle.e),
        abs(math.degrees(wrap_angle(vehicle.yaw))),
        t,
        vehicle.landed,
        (float(vehicle.n), float(vehicle.e)),
        pipeline.path,
    )


def run_autopilot_trial(
    sc: Scenario,
    seed: int,
    max_time: float = 150.0,
    camera_hz: float = CAMERA_HZ,
    trace: Trace | None = None,
    gnss_fix: str | None = None,
    xy_dist_max: float | None = None,
) -> Trial:
    """The other landing path: the simulated autopilot (profile ardupilot-4) returns as RTL does
    (to the base's surveyed position, at its height, then RTL_LOIT_TIME) and flies LAND with
    ArduPilot's precision landing (sim/vehicle/plnd.py); the agent only feeds it LANDING_TARGET
    while it lands — each new detection once, unfiltered, in the body frame of its capture
    (`steering="autopilot"`), and sets its PLND_XY_DIST_MAX as the daemon does when LAND
    begins (`[precland.autopilot]`: 5 cm, relaxed after 180 s; `xy_dist_max` another radius, 2.5
    ArduPilot's default). Same start, wind, sensors and world as `run_trial`: its
    EKF position drifts with the same GNSS model and draws (`CopterGnss`: the scenario's fix type
    unless `gnss_fix` names another, RTK fixed by default), and the surveyed pad carries the same
    error (up to 2 cm with RTK, 1 m on a plain fix: `_survey_and_start`). The daemon's guard
    (asset_agent/precland/guard.py) flies too: on a fix short of RTK fixed a pad lost above the
    final stretch is retried by the agent in GUIDED and then abandoned ("aborted-climb", not
    landed), never left to the autopilot's blind descent. The heading
    is not the autopilot's to align (PLND steers position only), so it is reported as it lands."""
    from dataclasses import replace

    from pymavlink.dialects.v20 import ardupilotmega as mavlink

    from sim.vehicle.constants import GUIDED, LAND
    from sim.vehicle.copter import Copter, CopterConfig
    from sim.vehicle.guidance import Goal
    from sim.vehicle.habits import profile
    from sim.vehicle.standalone import OpenPad

    rng = np.random.default_rng(seed)
    a0, yaw0 = rng.uniform(0, 2 * math.pi), rng.uniform(-math.pi, math.pi)
    c = Copter(OpenPad(), CopterConfig(seed=seed, habits=profile("ardupilot-4")))
    # its GNSS as the agent path's: the same model, from the same generator (run_trial)
    gnss_model = MODELS[gnss_fix or sc.gnss]
    c.gnss = CopterGnss(GnssError(gnss_model, np.random.default_rng((seed, 2))))
    c.reading = c.gnss.reading(0.0)
    survey, start_ne = _survey_and_start(sc, rng, a0, gnss_model)
    start = (*start_ne, -(sc.start_height - SEAT_HEIGHT))
    c.dyn.state = replace(c.dyn.state, position=start, landed=False, yaw=yaw0)
    c.armed = c.dyn.motors_on = True
    c._was_landed = False
    c.mode = GUIDED
    sources = sc.sources
    camera = bool(sources & {"pattern", "aruco"})
    cfg = _config(sc, sources, None, mode="landing_target", steering="autopilot")
    pipeline = LandingPipeline(cfg, seed=seed)
    renderer = PadRenderer(effects=CameraEffects(noise_sigma=2.0), seed=seed) if camera else None
    det_cfg = DetectorConfig(use_frame=True, use_aruco="aruco" in sources)
    detector = PadDetector(cfg.pad, cfg.camera, det_cfg) if camera else None
    ir_cfg = IrSensorConfig()
    weather = trial_weather(sc.wind, sc.gust, seed)  # the world's wind model (precland_wind.py)
    # RTL's return: to where the base was surveyed (its home), at the start's height
    c.guidance.goal = Goal("goto", float(survey[0]), float(survey[1]), start[2])
    returned_t: float | None = None
    landing_t: float | None = None  # when LAND began: the agent's PLND_XY_DIST_MAX gate's clock
    gate = cfg.autopilot
    if xy_dist_max is not None:
        gate = gate.model_copy(update={"xy_dist_max_m": xy_dist_max})

    def pose() -> tuple[float, float, float, float, float, float]:
        st = c.dyn.state
        n, e, d = st.position
        return (n, e, SEAT_HEIGHT - d, st.roll, st.pitch, st.yaw)

    pipeline.set_pad_prior(survey - np.asarray(c.estimated_position()), 1.0)
    # as the daemon's, with its default cautious retry: a pad lost high on a poor fix is not
    # left to the autopilot's blind descent
    guard = LossGuard(cfg.model_copy(update={"retry": RetryConfig()}))
    dt, t, k, next_frame = 0.01, 0.0, 0, 0.01
    while t < max_time and not c.dyn.state.landed and not guard.held:
        c.tick(dt, t + dt, weather.flow_ne(t))  # the copter's Airflow adds shear, turbulence
        t += dt
        if landing_t is None:  # RTL's return, then LAND (after it, the guard's modes)
            est = c.estimated_position()
            if returned_t is None and math.dist(est[:2], survey[:2]) < RETURNED_M:
                returned_t = t
            if returned_t is not None and t - returned_t >= c.config.rtl_loiter_s:
                if not c.set_mode(LAND):
                    raise RuntimeError("the simulated autopilot refused LAND")
                landing_t = t
        if landing_t is not None:  # as the daemon sets it when its landing loop starts
            radius = gate.xy_dist_max_at(t - landing_t)
            if radius is not None and radius != c.param("PLND_XY_DIST_MAX"):
                c.set_param("PLND_XY_DIST_MAX", radius)
        p, st = pose(), c.dyn.state
        pipeline.vehicle(
            VehicleState(
                t,
                c.estimated_position(),
                (p[3], p[4], p[5]),
                tuple(st.velocity),
                c.reading.fix_type,
            )
        )
        if "ir" in sc.sensors and k % 2 == 0:
            ok, ax, ay = ir_reading(p, ir_cfg, rng)
            pipeline.ir(t, ok, ax, ay)
        if renderer is not None and detector is not None and t >= next_frame - 1e-9:
            next_frame += 1.0 / camera_hz
            pipeline.detections(t, detector.detect(renderer.render(p), p[3], p[4]))
        lt = pipeline.tick(t).landing_target if k % 3 == 0 else None
        if lt is not None and c.mode == LAND:  # the supervisor sends while the autopilot lands
            msg = mavlink.MAVLink_landing_target_message(
                lt.time_usec, lt.target_num, lt.frame, lt.angle_x, lt.angle_y, lt.distance,
                lt.size_x, lt.size_y, lt.x, lt.y, lt.z, list(lt.q), lt.type, lt.position_valid,
            )  # fmt: skip
            c.handle(msg, None, t)
        if landing_t is not None and k % 10 == 0:  # the daemon's guard, at its 10 Hz
            _guard_step(c, guard, pipeline, t)
        if trace is not None:  # the PLND estimator's target minus vehicle while it has one
            found = c.plnd is not None and c.plnd.state == "found"
            trace.record(t, st.position[:2], p[2], c.plnd.rel_out if found else None)  # type: ignore[union-attr]
        k += 1
    st = c.dyn.state
    return Trial(
        c.pad_distance(),
        abs(math.degrees(wrap_angle(st.yaw))),
        t,
        st.landed,
        (float(st.position[0]), float(st.position[1])),
        "aborted-climb" if guard.held else "autopilot",
    )


def _guard_step(c: Any, guard: LossGuard, pipeline: LandingPipeline, t: float) -> None:
    """One step of the daemon's guard (asset_agent/precland/guard.py) on the simulated
    autopilot: GUIDED and velocity setpoints (SET_POSITION_TARGET_LOCAL_NED) while the agent
    flies its retry or abort, LAND again when the pad is back in view."""
    from pymavlink.dialects.v20 import ardupilotmega as mavlink

    from sim.vehicle.constants import GUIDED, LAND

    state = pipeline.state_at(t)
    if state is None:
        return
    act = guard.step(t, pipeline.kalman.updates, pipeline.kalman.estimate(), state)
    if act.kind == "take" and not c.set_mode(GUIDED):
        raise RuntimeError("the simulated autopilot refused GUIDED")
    if act.kind == "land" and not c.set_mode(LAND):
        raise RuntimeError("the simulated autopilot refused LAND")
    if act.setpoint is not None:
        sp = act.setpoint
        msg = mavlink.MAVLink_set_position_target_local_ned_message(
            int(t * 1000), 1, 1, 1, VELOCITY_ONLY, 0, 0, 0, sp.vn, sp.ve, sp.vd, 0, 0, 0, 0, 0
        )
        c.handle(msg, None, t)


def per_source_errors(heights: Sequence[float], n: int, seed: int = 0) -> list[dict]:
    """The paper's per-source error against altitude: mean horizontal / vertical / heading error
    of each vision element on rendered frames (any yaw, tilt up to 15°)."""
    rng = np.random.default_rng(seed)
    renderer = PadRenderer(effects=CameraEffects(noise_sigma=2.0), seed=seed)
    detector = PadDetector()
    rows = []
    for h in heights:
        acc: dict[str, list[tuple[float, float, float]]] = {"pattern": [], "aruco": []}
        for _ in range(n):
            tilt, az = math.radians(15) * rng.random(), rng.uniform(0, 2 * math.pi)
            off, oa = 0.15 * h * rng.random(), rng.uniform(0, 2 * math.pi)
            yaw = rng.uniform(-math.pi, math.pi)
            pose = (
                off * math.cos(oa),
                off * math.sin(oa),
                h,
                tilt * math.cos(az),
                tilt * math.sin(az),
                yaw,
            )
            det = detector.detect(renderer.render(pose), pose[3], pose[4])
            c, s = math.cos(yaw), math.sin(yaw)
            tx, ty = c * -pose[0] + s * -pose[1], -s * -pose[0] + c * -pose[1]
            for el in (det.pattern, det.aruco):
                if el is not None:
                    hd = (
                        abs(math.degrees(wrap_angle(el.heading + yaw)))
                        if el.heading is not None
                        else 0.0
                    )
                    acc[el.source].append((math.hypot(el.x - tx, el.y - ty), abs(el.z - h), hd))
        row: dict = {"height_m": h}
        for src, v in acc.items():
            if v:
                a = np.array(v)
                row[src] = {
                    "rate": len(v) / n,
                    "horizontal_cm": round(100 * float(a[:, 0].mean()), 3),
                    "vertical_cm": round(100 * float(a[:, 1].mean()), 3),
                    "heading_deg": round(float(a[:, 2].mean()), 3),
                }
            else:
                row[src] = None
        rows.append(row)
    return rows


def _row(trials: list[Trial], name: str) -> dict:
    """A row's figures: errors over the trials that landed (None when none did), and how many
    trials took each landing path."""
    landed = [tr for tr in trials if tr.landed]
    errs = [100 * tr.error_m for tr in landed]
    paths: dict[str, int] = {}
    for tr in trials:
        paths[tr.path] = paths.get(tr.path, 0) + 1
    return {
        "landed": len(landed),
        "mean_cm": round(statistics.fmean(errs), 2) if landed else None,
        "max_cm": round(max(errs), 2) if landed else None,
        "heading_deg": round(statistics.fmean(tr.heading_deg for tr in landed), 2)
        if landed
        else None,
        "time_s": round(statistics.fmean(tr.time_s for tr in trials), 1),
        "paths": paths,
        "published": PUBLISHED.get(name),
    }


def main(argv: Sequence[str] | None = None) -> int:
    """Run the chosen scenarios and print the table (and one JSON object last with --json)."""
    ap = argparse.ArgumentParser(
        prog="aerobase sim precland-eval", description=__doc__.splitlines()[0]
    )
    ap.add_argument("--trials", type=int, default=5)
    ap.add_argument(
        "--scenario",
        action="append",
        choices=[*SCENARIOS, PER_SOURCE],
        help="repeatable; default all",
    )
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--vehicle", choices=list(VEHICLES), default="shared")
    ap.add_argument(
        "--motion",
        choices=["velocity", "position"],
        help="what predicts the agent's filter: the autopilot's velocity or its position "
        "deltas (default: the agent's configuration)",
    )
    ap.add_argument(
        "--camera-hz",
        type=float,
        default=CAMERA_HZ,
        help="the camera's frame rate (default 33.3; the control loop stays at 33.3 Hz)",
    )
    ap.add_argument(
        "--path",
        choices=["agent", "autopilot", "both"],
        default="both",
        help="who steers the descent: the agent (its filter and velocity commands), the "
        "autopilot (ArduPilot PLND fed our detections; rows marked [autopilot PLND]), or both",
    )
    ap.add_argument(
        "--report",
        type=Path,
        help="write report.md, touchdown.png and error_vs_time.png (matplotlib) into this folder",
    )
    ap.add_argument(
        "--trace",
        choices=list(SCENARIOS),
        help="the scenario whose first trial the report follows through time (default: the "
        "first one run)",
    )
    ap.add_argument(
        "--gnss",
        choices=list(MODELS),
        help="the GNSS fix type of every row, on both paths (default: each scenario's, RTK fixed unless "
        "its name says float or 3d)",
    )
    ap.add_argument(
        "--plnd-xy-dist-max",
        type=float,
        metavar="M",
        help="the autopilot path's PLND_XY_DIST_MAX while it lands (default: the agent's "
        "[precland.autopilot], 0.05 m; 2.5 is ArduPilot's default, as before the agent set it)",
    )
    ap.add_argument(
        "--max-time",
        type=float,
        default=150.0,
        metavar="S",
        help="simulated seconds a trial may last (default 150); one still in the air then is "
        "reported not landed",
    )
    ap.add_argument("--json", action="store_true")
    argv = list(sys.argv[1:] if argv is None else argv)
    args = ap.parse_args(argv)
    motion = args.motion or PrecisionLandingConfig().kalman.motion
    chosen = args.scenario or [*SCENARIOS, PER_SOURCE]
    results: dict = {
        "trials": args.trials,
        "scenarios": {},  # the agent steers the descent
        "autopilot": {},  # the simulated autopilot's PLND lands on our detections
        "vehicle_model": args.vehicle,
        "motion": motion,
        "camera_hz": round(args.camera_hz, 2),
        "gnss": args.gnss,
        "plnd_xy_dist_max": args.plnd_xy_dist_max,
        "max_time_s": args.max_time,
        "seed": args.seed,
        "seeds": [args.seed * 1000 + i for i in range(args.trials)],  # the same for every row
        "command": " ".join(["aerobase sim precland-eval", *argv]),
    }
    touchdowns: dict[str, list[Trial]] = {}
    traces: dict[str, Trace] = {}
    traced = args.trace or next((n for n in chosen if n != PER_SOURCE), None)
    print(
        f"{'scenario':<32}{'landed':>8}{'mean cm':>9}{'max cm':>8}{'hdg °':>7}{'time s':>8}   published (cm, mean / max)"
    )
    paths = ["agent", "autopilot"] if args.path == "both" else [args.path]
    for name in chosen:
        if name == PER_SOURCE:
            continue
        for path in paths:
            if path == "autopilot" and SCENARIOS[name].cautious:
                continue  # the autopilot's own retry: the same flight as the plain scenario
            label = name if path == "agent" else f"{name} [autopilot PLND]"
            sc, trials, started = SCENARIOS[name], [], time.monotonic()
            print(  # live progress, on stderr: the table on stdout stays parseable
                f"{label}: {args.trials} trials, seeds {results['seeds'][0]}-"
                f"{results['seeds'][-1]}, wind {sc.wind:g} m/s, gust {sc.gust:g} m/s",
                file=sys.stderr,
                flush=True,
            )
            for i in range(args.trials):
                seed = args.seed * 1000 + i
                trace = None
                if name == traced and i == 0 and args.report is not None:
                    trace = traces[label] = Trace()
                if path == "agent":
                    tr = run_trial(
                        sc,
                        seed,
                        vehicle_model=args.vehicle,
                        motion=motion,
                        camera_hz=args.camera_hz,
                        trace=trace,
                        gnss_fix=args.gnss,
                        max_time=args.max_time,
                    )
                else:
                    tr = run_autopilot_trial(
                        sc,
                        seed,
                        camera_hz=args.camera_hz,
                        trace=trace,
                        gnss_fix=args.gnss,
                        xy_dist_max=args.plnd_xy_dist_max,
                        max_time=args.max_time,
                    )
                trials.append(tr)
                print(  # live progress, on stderr: the table on stdout stays parseable
                    f"  {label}: trial {i + 1}/{args.trials} (seed {seed}) "
                    f"{100 * tr.error_m:.1f} cm in {tr.time_s:.0f} s, {tr.path}"
                    + ("" if tr.landed else ", not landed"),
                    file=sys.stderr,
                    flush=True,
                )
            row = _row(trials, name)
            row["errors_cm"] = [round(100 * tr.error_m, 2) for tr in trials]  # seed by seed
            print(
                f"{label}: done in {time.monotonic() - started:.0f} s of wall time",
                file=sys.stderr,
                flush=True,
            )
            touchdowns[label] = trials
            results["scenarios" if path == "agent" else "autopilot"][name] = row
            mean, worst, heading = (
                "-" if row[k] is None else f"{row[k]:.1f}"
                for k in ("mean_cm", "max_cm", "heading_deg")
            )
            print(
                f"{label:<32}{row['landed']:>5}/{len(trials):<2}{mean:>9}"
                f"{worst:>8}{heading:>7}{row['time_s']:>8.1f}   "
                f"{row['published'] or ''}",
                flush=True,
            )
            if args.report is not None:  # rewritten as each row comes: a run cut short keeps it
                write_report(args.report, results, touchdowns, SCENARIOS, traces)
    if PER_SOURCE in chosen:
        rows = per_source_errors(
            (0.5, 1.0, 2.0, 3.0, 4.0, 5.0, 6.0), max(args.trials, 5) * 2, args.seed
        )
        results[PER_SOURCE] = rows
        print(
            "\nper-source error vs altitude (mean; horizontal cm / vertical cm / heading °, detection rate)"
        )
        print("paper (simulated): pattern 11.6 / 2.9 / 0.12, ArUco 0.4 / 7.8 / 0.16")
        for r in rows:
            cells = []
            for src in ("pattern", "aruco"):
                v = r[src]
                cells.append(
                    f"{src} "
                    + (
                        "-"
                        if v is None
                        else f"{v['horizontal_cm']:.2f} / {v['vertical_cm']:.2f} / {v['heading_deg']:.2f} ({v['rate']:.0%})"
                    )
                )
            print(f"  {r['height_m']:>4.1f} m   " + "   ".join(cells))
    if args.json:
        print(json.dumps(results))
    return 0


if __name__ == "__main__":
    sys.exit(main())
