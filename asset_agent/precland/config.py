"""Every precision-landing parameter, in one pydantic model: `PrecisionLandingConfig`."""

from __future__ import annotations

import math
from typing import Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

SOURCES = ("pattern", "aruco", "ir", "frame")


class _Model(BaseModel):
    model_config = ConfigDict(frozen=True, extra="forbid")


class PadGeometry(_Model):
    """The pad marker as built (paper §2.5.1): pad frame x forward (P5 → P1), y right, metres."""

    pattern_radius: float = 0.375  # circle through P1, P2, P3 (75 cm diameter)
    point_diameter: float = 0.10
    frame_outer: float = 1.10
    frame_width: float = 0.05
    aruco_size: float = 0.10
    aruco_centre: tuple[float, float] = (0.0, 0.0)
    aruco_dictionary: str = "DICT_4X4_50"
    aruco_id: int = 0
    beacon_xy: tuple[float, float] = (0.0, 0.0)

    def pattern_points(self) -> dict[str, tuple[float, float]]:
        """P1..P6: triangle vertices on the 75 cm circle and where its incircle touches the sides."""
        r = self.pattern_radius
        angles = (0.0, 2 * math.pi / 3, -2 * math.pi / 3)
        v = {f"P{i + 1}": (r * math.cos(a), r * math.sin(a)) for i, a in enumerate(angles)}

        def mid(a: str, b: str) -> tuple[float, float]:
            return ((v[a][0] + v[b][0]) / 2, (v[a][1] + v[b][1]) / 2)

        return {**v, "P4": mid("P1", "P2"), "P5": mid("P2", "P3"), "P6": mid("P3", "P1")}

    def aruco_corners(self) -> np.ndarray:
        """The marker's corners in OpenCV's order (top-left, top-right, ...; top = +x)."""
        cx, cy = self.aruco_centre
        h = self.aruco_size / 2
        return np.array([(cx + h, cy - h), (cx + h, cy + h), (cx - h, cy + h), (cx - h, cy - h)])


class CameraModel(_Model):
    """Downward camera: intrinsics, distortion, and its position on the vehicle (body FRD, m).

    Mounted looking down with the image's top towards the nose: camera x = body y (right),
    camera y = -body x, camera z = body z (down).
    """

    width: int = 640
    height: int = 480
    fx: float = 460.0
    fy: float = 460.0
    cx: float = 319.5
    cy: float = 239.5
    dist: tuple[float, float, float, float, float] = (0.0, 0.0, 0.0, 0.0, 0.0)
    offset_body: tuple[float, float, float] = (0.0, 0.0, 0.0)

    def matrix(self) -> np.ndarray:
        """The 3x3 camera matrix K."""
        return np.array([[self.fx, 0, self.cx], [0, self.fy, self.cy], [0, 0, 1]], dtype=np.float64)


class DetectorConfig(_Model):
    """Thresholds of the detector; elements can be switched off one by one."""

    use_frame: bool = True
    use_pattern: bool = True
    use_aruco: bool = True
    value_floor: int = 60  # never threshold Value below this
    value_fraction: float = 0.45  # threshold = fraction x the 99.9th percentile of Value
    local_contrast: int = 40  # and this much above the local background (0 disables): glare
    background_cell_px: int = 8  # the background is estimated on a grid of this cell size
    background_kernel_cells: int = 9  # structures narrower than this many cells are foreground
    frame_hole_ratio: tuple[float, float] = (0.82, 0.97)  # inner/outer side of the frame ring
    min_frame_side_px: float = 20.0
    circle_fill_min: float = 0.72  # blob area / enclosing-circle area
    min_blob_area_px: float = 3.0
    max_blob_area_fraction: float = 0.2
    min_saturation_gap: float = 0.2  # K-means centroids must differ this much in saturation
    match_tolerance: float = 0.15  # of |P1P5|: predicted-vs-found point distance
    max_residual: float = 0.05  # of |P1P5|: RMS residual of the six-point fit
    aruco_max_residual: float = 0.05  # of the marker side
    aruco_min_side_px: float = 24.0  # smaller markers give centimetre-poor heights: ignore them
    # the reported uncertainty of a detection (1-sigma of the pad centre, per axis, metres):
    # height x sqrt(attitude_sigma² + (pixel_sigma² + fit residual²) / points), the attitude
    # used to level the points being the error that does not average over the points
    pixel_sigma_px: float = Field(default=1.0, gt=0.0)  # one detected point (centroid, corner)
    attitude_sigma_rad: float = Field(default=0.004, ge=0.0)  # the autopilot's roll and pitch


class SourceConfig(_Model):
    """A fusion source: its weight and how long a reading counts as new."""

    weight: float = 1.0
    freshness_s: float = 0.2


class FusionConfig(_Model):
    """Thesis truth table: weighted average of new values, the single new one, the last one while
    younger than hold_s, else no target."""

    sources: dict[str, SourceConfig] = Field(
        default_factory=lambda: {
            "pattern": SourceConfig(weight=1.0, freshness_s=0.2),
            "aruco": SourceConfig(weight=4.0, freshness_s=0.2),
            "ir": SourceConfig(weight=1.0, freshness_s=0.1),
        }
    )
    hold_s: float = 1.0


class FaultConfig(_Model):
    """Fault injection for one source; all zero / None disables it."""

    r_drop: float = Field(default=0.0, ge=0.0, le=1.0)
    p_keep: float = Field(default=0.0, ge=0.0)
    p_drop: float = Field(default=0.0, ge=0.0)
    fail_below_m: float | None = None
    fail_above_m: float | None = None


class KalmanConfig(_Model):
    """Noise of the relative-position filter, in physical units: whatever the rates of the
    autopilot's states (predictions) and of the camera (updates), the filter behaves the same.

    Process noise is a random walk per second (and per metre moved): over a prediction of dt
    seconds and d metres the variance grows by `position_noise_m_per_sqrt_s`² x dt +
    `position_noise_m_per_sqrt_m`² x d, so one prediction over 1 s adds what 100 of 10 ms add.
    Measurement noise is per reading (the detector's reported sigma where it reports one, else
    the vision model at the measured height), and readings closer together than
    `vision_error_correlation_s` count as one: the detector's error comes from the pad's image,
    which changes little between two frames 33 ms apart, so 30 frames a second do not carry six
    times the information of 5 (the variance is inflated by correlation time / interval).
    """

    initial_sigma_m: float = 1.5
    initial_heading_sigma: float = math.pi
    # what predicts the filter horizontally: the autopilot's position deltas (they carry the
    # GNSS drift) or, once it has had a measurement, its velocity (LOCAL_POSITION_NED vx, vy:
    # GNSS Doppler + IMU) integrated; position deltas when the states carry no velocity
    motion: Literal["position", "velocity"] = "position"
    # position-delta random walk: the GNSS drift per sqrt(second), by the fix type the
    # autopilot reports (GPS_RAW_INT fix_type: 6 RTK fixed, 5 RTK float, else a plain fix),
    # and the error per sqrt(metre moved). RTK fixed: ~1 cm of receiver noise smoothed over
    # ~1 s plus mm/sqrt(s) of slow multipath drift, ~0.8 cm over a 2.4 s blind descent; float:
    # 0.25 m wandering over 60 s; a plain fix: 0.5 m over 120 s (bench/precland_gnss.py)
    gnss_drift_rtk_fixed_m_per_sqrt_s: float = Field(default=0.005, ge=0.0)
    gnss_drift_rtk_float_m_per_sqrt_s: float = Field(default=0.046, ge=0.0)
    gnss_drift_3d_m_per_sqrt_s: float = Field(default=0.065, ge=0.0)
    # the drift when the fix type is unknown (the former per-update tuning's effect at the
    # evaluation's 100 Hz states)
    position_noise_m_per_sqrt_s: float = Field(default=0.005, ge=0.0)
    position_noise_m_per_sqrt_m: float = Field(default=0.002, ge=0.0)
    velocity_noise_m_per_sqrt_s: float = Field(default=0.03, ge=0.0)  # integrated velocity
    # the horizontal velocity's slow bias (IMU, EKF corrections), learnt while measurements
    # come in; tau 0: not estimated
    velocity_bias_sigma: float = 0.03  # m/s
    velocity_bias_tau_s: float = 30.0
    heading_noise_rad_per_sqrt_s: float = Field(default=0.001, ge=0.0)
    # per reading, m per m of height and its floor (pixel error); with the correlation time
    # below, the information per second the former per-reading 1 cm/m, 3 mm floor gave at the
    # evaluation's 33 Hz camera (x sqrt(1 / (33 Hz x 0.2 s)))
    vision_sigma_per_metre: float = Field(default=0.004, gt=0.0)
    vision_sigma_floor: float = Field(default=0.0012, gt=0.0)
    # readings closer together than this share their error (0: every reading independent)
    vision_error_correlation_s: float = Field(default=0.2, ge=0.0)
    heading_sigma: float = math.radians(1.0)  # rad, per reading

    def vision_sigma(self, height_m: float) -> float:
        """The vision model's 1-sigma of one reading taken `height_m` above the pad."""
        return max(self.vision_sigma_floor, self.vision_sigma_per_metre * abs(height_m))


class ControlConfig(_Model):
    """Companion-mode landing: conical acceptance volume (paper eq. 3, 4), gains and limits."""

    min_pos_error: float = 0.03
    max_pos_error: float = 0.5
    kp_xy: float = 2.0  # tuned on the simulated vehicles; retune on the airframe
    ki_xy: float = 0.5  # integral of the horizontal error while approaching (steady wind)
    max_integral_speed: float = 0.5  # m/s the integral term may add
    kp_z: float = 0.5
    max_speed_xy: float = 1.5
    max_descent: float = 1.0
    max_climb: float = 1.0
    slow_height: float = 0.5  # the slow final stretch, above touchdown
    slow_descent: float = 0.1
    # inside the cone, descend at least this fast (m/s; kp_z x a alone slows to nothing near
    # the seat: the last 10 cm took 3 s, gusts swung the vehicle 7 cm off meanwhile and the
    # hand-over landed it there — fused-wind8 seed 1012 8.2 cm, thesis-field seed 1009 6.5 cm)
    final_descent_floor: float = Field(default=0.1, ge=0.0)
    final_inside_cone_only: bool = True  # in the final stretch, hold altitude outside the cone
    # and this close to touchdown climb back instead (at slow_descent), no hand-over until
    # inside: holding there, the descent's momentum sank the vehicle onto the seat off-centre
    # (thesis-field seed 1012, 7.2 cm)
    back_off_height: float = Field(default=0.05, ge=0.0)
    max_heading_error_deg: float = 5.0
    kp_yaw: float = 1.0
    max_yaw_rate: float = 0.8
    heading_offset_deg: float = 0.0  # vehicle yaw - pad yaw when seated on the contacts
    touchdown_height: float = 0.25  # camera height above the pad when seated on the contacts
    land_margin: float = 0.02  # hand over to the autopilot's landing this close to touchdown
    landing_target_rate_hz: float = Field(default=20.0, ge=10.0)


class RetryConfig(_Model):
    """The thesis's cautious landing: pause, climb back, retry, then descend blind."""

    cautious: bool = True
    pause_s: float = 2.0
    default_height: float = 5.0
    climb_speed: float = 0.8
    reached_tolerance_m: float = 0.2
    climb_margin_m: float = 0.5  # climb this far above where the target was last seen
    # a climb back that has not got there in this long counts as there (12 m/s, the autopilot
    # path, seed 1019: blown 20-50 m off the goal, it went on climbing at 0.1 m/s to 22 m)
    climb_timeout_s: float = Field(default=20.0, gt=0.0)
    max_attempts: int = 3
    blind_descent: float = 0.5  # ArduPilot's LAND_SPEED: the touchdown speed, blind
    # after losing a target it had seen (height known from vision): descend this fast, flaring
    # at blind_flare_decel to blind_descent this far above touchdown; blind, the estimate drifts
    # with time, so the less time the better (blind_fast_descent = blind_descent: off)
    blind_fast_descent: float = 1.5  # ArduPilot's WPNAV_SPEED_DN
    blind_flare_decel: float = 1.5  # m/s², half the vehicle's acceleration limit
    blind_flare_margin_m: float = 0.1
    blind_slow_final: bool = False  # slowing down blind only lets the GNSS drift grow
    # in the final stretch, blind within this long of the last sighting, hold height to steer
    # back inside the cone first (the estimate is still good); later it has drifted with the fix
    # and holding only adds drift: descend as it is (marker failing below 3 m on a 3D fix, held:
    # 13.3 / 29.3 cm against 11.65 / 26.01)
    blind_recentre_s: float = Field(default=2.0, ge=0.0)
    # a blind descent keeps to the approach's cone (outside it: slowing to its surface, holding
    # the final stretch) this close to touchdown, where it would land beside the pad; higher up
    # the wind is stronger (its log profile) and waiting there let 12 m/s carry the vehicle 11 m
    # off (seed 1010), where descending brought the pad back into view
    blind_wait_height_m: float = Field(default=2.0, ge=0.0)
    # a blind descent that has waited outside the cone this long in all (the wind holds the
    # vehicle off the pad) climbs to `search.abort_height_m` and holds ("aborted-climb") rather
    # than land beside the pad
    blind_hold_max_s: float = Field(default=10.0, gt=0.0)
    # a target lost with no retry left on a fix short of RTK fixed (float, plain, unknown):
    # descend blind only from this close to touchdown (the final stretch: well under a second
    # blind), else climb to `search.abort_height_m` and hold ("aborted-climb"), never landing
    # blind on its drift (issue 19: the marker failing below 3 m landed 8.0 / 14.7 cm on RTK
    # float, 11.7 / 26.0 on a 3D fix). None: blind from any height on any fix (the thesis)
    blind_max_height_unfixed_m: float | None = Field(default=0.5, ge=0.0)
    recentre: bool = True  # after a retry, centre over the target before descending again
    recentre_tolerance_m: float = 0.03
    recentre_settle_s: float = 1.0  # vision fresh this long first: the filter has converged
    recentre_timeout_s: float = 10.0  # then descend anyway


class SearchConfig(_Model):
    """When the pad is not in view at the approach altitude: hover `acquire_s`, then fly an
    expanding square around the base's surveyed position at that altitude (legs growing by
    `footprint_fraction` of the camera's footprint there, the pad wholly in view), bounded by
    `max_radius_m` and `max_time_s`. Then the fallback: on an RTK fixed GNSS, descend on it over
    the surveyed pad (its accuracy is the survey's in the base's RTK frame) and take the pad
    when it comes into view; on a float or plain fix climb to `abort_height_m` and hold there,
    reporting "aborted-climb" — never a blind landing on them."""

    enabled: bool = True
    acquire_s: float = Field(default=2.0, ge=0.0)
    footprint_fraction: float = Field(default=0.8, gt=0.0, le=1.0)
    pad_half_size_m: float = 0.55  # the masking frame's half side: all of it must be in view
    min_leg_m: float = Field(default=1.0, gt=0.0)
    max_radius_m: float = Field(default=10.0, gt=0.0)
    max_time_s: float = Field(default=60.0, gt=0.0)
    speed: float = Field(default=2.0, gt=0.0)
    reached_tolerance_m: float = 0.5
    rtk_fallback: bool = True  # False: climb and report on any fix
    abort_height_m: float = 15.0  # above the pad


class AutopilotDescentConfig(_Model):
    """Mode landing_target: what the agent asks of the autopilot's own LAND while it lands on our
    LANDING_TARGETs. ArduPilot holds LAND's descent while its target estimate is farther than
    PLND_XY_DIST_MAX (default 2.5 m) and otherwise descends wherever the wind has pushed the
    vehicle; at `xy_dist_max_m` (the contacts' 5 cm) it descends only while within that of the
    pad, so a gust pauses the descent instead of moving the touchdown — slower, and nearer (the
    figures: README, *The descent gate*). The vehicle resumes its descent at the edge of the
    radius, so a tighter one lands nearer and later. A landing still going after
    `relax_after_s` (held by wind it cannot beat) gets `relaxed_xy_dist_max_m` (ArduPilot's
    default) and lands as it can. Set when the landing loop starts, each landing; None leaves the
    autopilot's value alone (an autopilot without the parameter answers nothing: logged)."""

    xy_dist_max_m: float | None = Field(default=0.05, ge=0.0)
    relax_after_s: float = Field(default=180.0, gt=0.0)
    relaxed_xy_dist_max_m: float = Field(default=2.5, ge=0.0)

    def xy_dist_max_at(self, landing_s: float) -> float | None:
        """PLND_XY_DIST_MAX for a landing `landing_s` seconds old (None: leave it alone)."""
        if self.xy_dist_max_m is None:
            return None
        return self.xy_dist_max_m if landing_s < self.relax_after_s else self.relaxed_xy_dist_max_m


class PrecisionLandingConfig(_Model):
    """The whole precision-landing configuration of the agent."""

    mode: Literal["landing_target", "companion"] = "companion"
    # mode landing_target: who steers the descent. "agent": a LANDING_TARGET every control step
    # from the agent's own filter (the autopilot goes where it is told); "autopilot": each new
    # measurement once, unfiltered, in the body frame of its capture, for the autopilot's own
    # estimator and descent (ArduPilot PLND_TYPE=1, PX4's landing-target estimator)
    steering: Literal["agent", "autopilot"] = "agent"
    pad: PadGeometry = PadGeometry()
    camera: CameraModel = CameraModel()
    detector: DetectorConfig = DetectorConfig()
    fusion: FusionConfig = FusionConfig()
    faults: dict[str, FaultConfig] = Field(default_factory=dict)
    kalman: KalmanConfig = KalmanConfig()
    control: ControlConfig = ControlConfig()
    retry: RetryConfig = RetryConfig()
    search: SearchConfig = SearchConfig()
    autopilot: AutopilotDescentConfig = AutopilotDescentConfig()
