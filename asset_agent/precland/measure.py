"""Per-source measurements in one frame: the pad centre relative to the vehicle, in NED.

Vision elements arrive relative to the camera in the heading frame (see `geometry`); the IR
sensor gives only a direction, scaled by the current height estimate. Both are rotated by the
vehicle's yaw and shifted by the camera's mounting offset, so fusion and the Kalman filter work
in the same local NED axes as the autopilot's position deltas.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from asset_agent.precland.config import CameraModel, PadGeometry
from asset_agent.precland.geometry import (
    BODY_FROM_CAM,
    ElementPose,
    rotation_world_from_body,
    wrap_angle,
)

Attitude = tuple[float, float, float]
"""(roll, pitch, yaw) in radians."""


@dataclass(frozen=True)
class Measurement:
    """One source's reading: pad centre minus vehicle (NED, m), pad yaw (rad) if known, quality,
    and its 1-sigma per axis (m) when the source reports one."""

    source: str
    t: float
    rel_ned: tuple[float, float, float]
    heading: float | None
    quality: float = 1.0
    sigma_m: float | None = None

    @property
    def height(self) -> float:
        """Height of the vehicle above the pad."""
        return self.rel_ned[2]


def _camera_offset_ned(camera: CameraModel, attitude: Attitude) -> np.ndarray:
    return rotation_world_from_body(*attitude) @ np.asarray(camera.offset_body, dtype=np.float64)


def from_element(
    element: ElementPose, t: float, attitude: Attitude, camera: CameraModel
) -> Measurement:
    """A detector element's pose as a measurement."""
    yaw = attitude[2]
    c, s = math.cos(yaw), math.sin(yaw)
    rel = np.array([c * element.x - s * element.y, s * element.x + c * element.y, element.z])
    rel += _camera_offset_ned(camera, attitude)
    heading = None if element.heading is None else wrap_angle(element.heading + yaw)
    return Measurement(
        element.source,
        t,
        (float(rel[0]), float(rel[1]), float(rel[2])),
        heading,
        element.quality,
        element.sigma_m,
    )


def from_ir(
    angle_x: float,
    angle_y: float,
    t: float,
    attitude: Attitude,
    height: float,
    camera: CameraModel,
    pad: PadGeometry | None = None,
    pad_yaw: float | None = None,
    sigma_m: float | None = None,
) -> Measurement:
    """An IR direction as a measurement, scaled to `height` (the camera's height above the pad),
    with the 1-sigma `sigma_m` the caller gives it."""
    ray_cam = np.array([math.tan(angle_x), math.tan(angle_y), 1.0])
    ray = rotation_world_from_body(*attitude) @ BODY_FROM_CAM @ ray_cam
    rel = ray * (height / max(ray[2], 1e-6)) + _camera_offset_ned(camera, attitude)
    bx, by = (pad or PadGeometry()).beacon_xy
    if (bx or by) and pad_yaw is not None:  # the beacon is off-centre: move to the pad centre
        c, s = math.cos(pad_yaw), math.sin(pad_yaw)
        rel -= np.array([c * bx - s * by, s * bx + c * by, 0.0])
    return Measurement("ir", t, (float(rel[0]), float(rel[1]), float(rel[2])), None, 1.0, sigma_m)
