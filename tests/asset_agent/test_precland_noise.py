"""The filter's noise in physical units from what the sensors report (issue 19): the GNSS drift
follows the autopilot's fix type, and a detection's reported sigma is what the filter trusts."""

from __future__ import annotations

import math

import numpy as np
import pytest

from asset_agent.precland.config import DetectorConfig, KalmanConfig, PrecisionLandingConfig
from asset_agent.precland.detect import Detections, PadDetector
from asset_agent.precland.fusion import Fusion
from asset_agent.precland.geometry import ElementPose
from asset_agent.precland.kalman import FIX_3D, FIX_RTK_FIXED, FIX_RTK_FLOAT, TargetKalman
from asset_agent.precland.measure import Measurement
from asset_agent.precland.pipeline import LandingPipeline, VehicleState
from sim.camera.render import CameraEffects, PadRenderer

K = KalmanConfig()


def blind_growth(fix: int | None, seconds: float = 2.4) -> float:
    """The filter's horizontal sigma growth over a blind hover of `seconds` at 100 Hz."""
    kf = TargetKalman(K)
    kf.reset((0.0, 0.0, 3.0), sigma_m=1e-6)
    for _ in range(round(seconds * 100)):
        kf.predict((0.0, 0.0, 0.0), 0.01, fix_type=fix)
    return math.sqrt(float(kf.p[0, 0]))


@pytest.mark.parametrize(
    ("fix", "drift"),
    [
        (FIX_RTK_FIXED, K.gnss_drift_rtk_fixed_m_per_sqrt_s),
        (FIX_RTK_FLOAT, K.gnss_drift_rtk_float_m_per_sqrt_s),
        (FIX_3D, K.gnss_drift_3d_m_per_sqrt_s),
        (None, K.position_noise_m_per_sqrt_s),
    ],
)
def test_the_gnss_drift_the_filter_assumes_follows_the_fix_type(fix, drift):
    assert blind_growth(fix) == pytest.approx(drift * math.sqrt(2.4), rel=1e-6)


def test_rtk_fixed_drifts_millimetres_over_a_blind_descent_a_plain_fix_centimetres():
    assert blind_growth(FIX_RTK_FIXED) < 0.01 < 0.05 < blind_growth(FIX_RTK_FLOAT)
    assert blind_growth(FIX_3D) > blind_growth(FIX_RTK_FLOAT)


def test_the_pipeline_predicts_with_the_fix_type_of_each_state():
    sigmas = {}
    for fix in (FIX_RTK_FIXED, FIX_3D):
        p = LandingPipeline(PrecisionLandingConfig())
        p.set_pad_prior((0.0, 0.0, 3.0), 1e-6)
        for k in range(101):
            p.vehicle(VehicleState(k * 0.01, (0.0, 0.0, -3.0), (0.0, 0.0, 0.0), None, fix))
        sigmas[fix] = math.sqrt(float(p.kalman.p[0, 0]))
    assert sigmas[FIX_RTK_FIXED] == pytest.approx(K.gnss_drift_rtk_fixed_m_per_sqrt_s, rel=1e-3)
    assert sigmas[FIX_3D] == pytest.approx(K.gnss_drift_3d_m_per_sqrt_s, rel=1e-3)


def test_a_detection_reports_its_sigma_from_attitude_pixels_and_fit():
    cfg = DetectorConfig()
    detector = PadDetector(config=cfg)
    renderer = PadRenderer(effects=CameraEffects(noise_sigma=2.0), seed=3)
    for h in (1.0, 3.0, 5.0):
        det = detector.detect(renderer.render((0.1, -0.05, h, 0.02, -0.03, 0.4)), 0.02, -0.03)
        for el, points in ((det.pattern, 6), (det.aruco, 4)):
            if el is None:
                continue
            floor = h * math.sqrt(
                cfg.attitude_sigma_rad**2 + (cfg.pixel_sigma_px / 460) ** 2 / points
            )
            assert el.sigma_m is not None
            # at least the attitude's and the pixels' part; the fit's residual on an idealised
            # render adds little
            assert floor * 0.99 < el.sigma_m < 1.5 * floor, (h, el)
    noisy = PadDetector(config=DetectorConfig(attitude_sigma_rad=0.02))
    det = noisy.detect(renderer.render((0.0, 0.0, 3.0, 0.0, 0.0, 0.0)))
    assert det.pattern is not None and det.pattern.sigma_m == pytest.approx(0.06, rel=0.05)


def test_fusion_carries_the_sigma_of_a_weighted_average():
    f = Fusion()
    f.submit(Measurement("pattern", 0.0, (0.1, 0.0, 3.0), None, 1.0, 0.02))
    f.submit(Measurement("aruco", 0.0, (0.0, 0.0, 3.0), None, 1.0, 0.01))
    target = f.step(0.05)
    assert target is not None and target.kind == "fused"
    # weights 1 and 4: sqrt(1 x 0.02² + 16 x 0.01²) / 5
    assert target.sigma_m == pytest.approx(math.sqrt(0.02**2 + 16 * 0.01**2) / 5)
    f.submit(Measurement("ir", 0.1, (0.0, 0.0, 3.0), None))
    f.submit(Measurement("aruco", 0.1, (0.0, 0.0, 3.0), None, 1.0, 0.01))
    assert f.step(0.12).sigma_m is None  # a reading without one: the filter's own model


def test_the_filter_trusts_a_detection_as_much_as_its_reported_sigma_never_more_than_the_model():
    moved = {}
    for sigma in (0.005, 0.05):
        p = LandingPipeline(PrecisionLandingConfig())
        p.set_pad_prior((0.0, 0.0, 3.0), 0.05)
        p.vehicle(VehicleState(0.0, (0.0, 0.0, -3.0), (0.0, 0.0, 0.0)))
        el = ElementPose("aruco", 0.1, 0.0, 3.0, None, 1.0, sigma)  # 10 cm forward (yaw 0: north)
        p.detections(0.0, Detections(None, None, el))
        p.tick(0.0)
        moved[sigma] = float(p.kalman.x[0])
    # K = P / (P + R): a reported 0.05 gives one half; a reported 0.005 is below the vision model
    # at 3 m (0.4 cm per metre: 1.2 cm), which it gets instead: 0.05² / (0.05² + 0.012²)
    assert moved[0.005] == pytest.approx(0.1 * 0.05**2 / (0.05**2 + 0.012**2), rel=1e-3)
    assert moved[0.05] == pytest.approx(0.05, rel=1e-3)
    assert np.isfinite(list(moved.values())).all()
