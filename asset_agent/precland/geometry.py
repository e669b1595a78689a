"""Frames, rotations and the level-camera rectification shared by the pose estimators.

Frames: NED world; FRD body; the *heading frame* is the body frame levelled (rotated by the
vehicle's yaw only): x forward, y right, z down. The camera looks down with camera x = body y,
camera y = -body x, camera z = body z.

Attitude correction: each detected pixel is undistorted, turned into a ray, rotated by the
vehicle's roll and pitch into the heading frame and divided by its z. The result is what a
*level* virtual camera of focal length 1 would see, in which the planar pad is an exact
similarity of its model — so the paper's ratios (eq. 1 and 2) hold exactly there:
offset = imageOffset × worldSize / imageSize and height = f × worldSize / imageSize (f = 1).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

from asset_agent.precland.config import CameraModel

BODY_FROM_CAM = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])


def rotation_world_from_body(roll: float, pitch: float, yaw: float) -> np.ndarray:
    """R (NED from FRD) for ZYX Euler angles."""
    cr, sr = math.cos(roll), math.sin(roll)
    cp, sp = math.cos(pitch), math.sin(pitch)
    cy, sy = math.cos(yaw), math.sin(yaw)
    return np.array(
        [
            [cp * cy, sr * sp * cy - cr * sy, cr * sp * cy + sr * sy],
            [cp * sy, sr * sp * sy + cr * cy, cr * sp * sy - sr * cy],
            [-sp, sr * cp, cr * cp],
        ]
    )


def wrap_angle(a: float) -> float:
    """The angle in [-pi, pi)."""
    return (a + math.pi) % (2 * math.pi) - math.pi


def level_normalised(
    pixels: np.ndarray, camera: CameraModel, roll: float, pitch: float
) -> np.ndarray:
    """Pixels (N, 2) → level virtual-camera coordinates (X/Z, Y/Z) in the heading frame."""
    pts = np.asarray(pixels, dtype=np.float64).reshape(-1, 1, 2)
    norm = cv2.undistortPoints(pts, camera.matrix(), np.asarray(camera.dist)).reshape(-1, 2)
    rays_cam = np.column_stack((norm, np.ones(len(norm))))
    rot = rotation_world_from_body(roll, pitch, 0.0) @ BODY_FROM_CAM
    rays = rays_cam @ rot.T
    z = rays[:, 2:3]
    z = np.where(z > 1e-6, z, 1e-6)
    return rays[:, :2] / z


@dataclass(frozen=True)
class Similarity:
    """q = scale · R(angle) · p + t, fitted by least squares, and its RMS residual."""

    scale: float
    angle: float
    tx: float
    ty: float
    rms: float


def fit_similarity(model: np.ndarray, observed: np.ndarray) -> Similarity:
    """Least-squares similarity from model points (N, 2) to observed points (N, 2)."""
    p = model[:, 0] + 1j * model[:, 1]
    q = observed[:, 0] + 1j * observed[:, 1]
    pm, qm = p.mean(), q.mean()
    dp, dq = p - pm, q - qm
    a = np.sum(dq * np.conj(dp)) / max(float(np.sum(np.abs(dp) ** 2)), 1e-12)
    b = qm - a * pm
    rms = float(np.sqrt(np.mean(np.abs(q - (a * p + b)) ** 2)))
    return Similarity(float(abs(a)), float(np.angle(a)), float(b.real), float(b.imag), rms)


def apply_similarity(sim: Similarity, points: np.ndarray) -> np.ndarray:
    """Map model points (N, 2) through the similarity."""
    p = points[:, 0] + 1j * points[:, 1]
    q = sim.scale * np.exp(1j * sim.angle) * p + (sim.tx + 1j * sim.ty)
    return np.column_stack((q.real, q.imag))


@dataclass(frozen=True)
class ElementPose:
    """Pad centre relative to the camera in the heading frame (x fwd, y right, z down = height),
    the pad's heading relative to the vehicle's (None when the element cannot tell), a quality in
    [0, 1], and the detector's 1-sigma of the centre per axis (m; None: not reported)."""

    source: str
    x: float
    y: float
    z: float
    heading: float | None
    quality: float
    sigma_m: float | None = None


def pose_from_similarity(
    source: str,
    sim: Similarity,
    quality: float,
    heading: bool,
    sigma_rad: float | None = None,
) -> ElementPose:
    """Paper eq. 1 and 2 in the level camera: height = 1 / scale, offset = t / scale; the
    centre's angular 1-sigma `sigma_rad` becomes metres at that height."""
    z = 1.0 / sim.scale
    return ElementPose(
        source,
        sim.tx * z,
        sim.ty * z,
        z,
        wrap_angle(sim.angle) if heading else None,
        quality,
        None if sigma_rad is None else sigma_rad * z,
    )
