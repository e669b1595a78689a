"""Renders the downward camera's view of the pad over a textured ground from the vehicle's pose.

Rendering inverse-maps the ground plane through a homography: for a pinhole camera the ground
plane (z = 0) maps to the image by H = K · [r1 r2 t], so cv2.warpPerspective of a mip-mapped,
high-resolution texture gives the exact perspective view in one pass per layer (ground, then the
pad composited with BORDER_TRANSPARENT). Optional effects are applied in the order light reaches
the sensor: exposure, glare, motion blur, lens distortion, sensor noise.

Frames: x right, y down in the image; the camera looks along body +z (down) with the image's top
towards the vehicle's nose, so camera = (body y, -body x, body z).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

from sim.camera.pad import ground_texture_pyramid, pad_texture_pyramid, texture_affine

Pose = tuple[float, float, float, float, float, float]
"""(north_m, east_m, up_m, roll, pitch, yaw) of the vehicle relative to the pad centre (radians)."""

CAM_FROM_BODY = np.array([[0.0, 1.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])


@dataclass(frozen=True)
class CameraIntrinsics:
    """Pinhole intrinsics plus OpenCV (k1, k2, p1, p2, k3) distortion; pixel centres at integers."""

    width: int = 640
    height: int = 480
    fx: float = 460.0
    fy: float = 460.0
    cx: float = 319.5
    cy: float = 239.5
    dist: tuple[float, float, float, float, float] = (0.0, 0.0, 0.0, 0.0, 0.0)

    def matrix(self) -> np.ndarray:
        """The 3x3 camera matrix K."""
        return np.array([[self.fx, 0, self.cx], [0, self.fy, self.cy], [0, 0, 1]], dtype=np.float64)


@dataclass(frozen=True)
class Glare:
    """A lens flare: an additive Gaussian blob at pixel (x, y) of the given radius and peak level."""

    x: float
    y: float
    radius: float = 60.0
    strength: float = 120.0


@dataclass(frozen=True)
class CameraEffects:
    """Optional image degradations; the defaults leave the ideal image untouched."""

    exposure: float = 1.0
    glare: Glare | None = None
    blur_px: float = 0.0
    blur_angle_deg: float = 0.0
    noise_sigma: float = 0.0


def rotation_world_from_body(roll: float, pitch: float, yaw: float) -> np.ndarray:
    """R (NED from FRD) for ZYX Euler angles."""
    cr, sr, cp, sp, cy, sy = (
        math.cos(roll),
        math.sin(roll),
        math.cos(pitch),
        math.sin(pitch),
        math.cos(yaw),
        math.sin(yaw),
    )
    return np.array(
        [
            [cp * cy, sr * sp * cy - cr * sy, cr * sp * cy + sr * sy],
            [cp * sy, sr * sp * sy + cr * cy, cr * sp * sy - sr * cy],
            [-sp, sr * cp, cr * cp],
        ]
    )


def ground_homography(
    intrinsics: CameraIntrinsics, pose: Pose, camera_offset: tuple[float, float, float] = (0, 0, 0)
) -> np.ndarray:
    """H mapping pad-frame ground points (x north, y east, 1) to ideal (undistorted) pixels."""
    n, e, up, roll, pitch, yaw = pose
    r_wb = rotation_world_from_body(roll, pitch, yaw)
    centre = np.array([n, e, -up]) + r_wb @ np.asarray(camera_offset, dtype=np.float64)
    r_cw = CAM_FROM_BODY @ r_wb.T
    m = np.column_stack((r_cw[:, 0], r_cw[:, 1], -r_cw @ centre))
    return intrinsics.matrix() @ m


def project_ground(
    intrinsics: CameraIntrinsics,
    pose: Pose,
    points_xy: np.ndarray,
    camera_offset: tuple[float, float, float] = (0, 0, 0),
) -> np.ndarray:
    """Pixel coordinates (with the lens distortion) of pad-frame ground points, shape (N, 2)."""
    pts = np.asarray(points_xy, dtype=np.float64).reshape(-1, 2)
    h = ground_homography(intrinsics, pose, camera_offset)
    ph = (h @ np.column_stack((pts, np.ones(len(pts)))).T).T
    ideal = ph[:, :2] / ph[:, 2:3]
    if not any(intrinsics.dist):
        return ideal
    k = intrinsics.matrix()
    norm = np.column_stack(((ideal[:, 0] - k[0, 2]) / k[0, 0], (ideal[:, 1] - k[1, 2]) / k[1, 1]))
    obj = np.column_stack((norm, np.ones(len(norm))))
    out, _ = cv2.projectPoints(obj, np.zeros(3), np.zeros(3), k, np.asarray(intrinsics.dist))
    return out.reshape(-1, 2)


def _pick_level(levels, gsd: float):
    chosen = levels[0]
    for res, img in levels:
        if res <= gsd * 1.05:
            chosen = (res, img)
    return chosen


class PadRenderer:
    """Renders 8-bit BGR frames of the pad and the ground for a given vehicle pose."""

    MARGIN = 96  # extra ideal-image border sampled by the distortion remap

    def __init__(
        self,
        intrinsics: CameraIntrinsics | None = None,
        effects: CameraEffects | None = None,
        seed: int = 0,
        camera_offset: tuple[float, float, float] = (0.0, 0.0, 0.0),
    ) -> None:
        self.intrinsics = intrinsics or CameraIntrinsics()
        self.effects = effects or CameraEffects()
        self.camera_offset = camera_offset
        self._rng = np.random.default_rng(seed)
        self._pad = pad_texture_pyramid()
        self._ground_side, self._ground = ground_texture_pyramid()
        self._maps: tuple[np.ndarray, np.ndarray] | None = None
        self._glare_img: np.ndarray | None = None

    def set_effects(self, effects: CameraEffects) -> None:
        """Change the image degradations (takes effect from the next frame)."""
        self.effects = effects
        self._glare_img = None

    def render(self, pose: Pose) -> np.ndarray:
        """One frame (height x width x 3, uint8) seen from `pose`."""
        intr = self.intrinsics
        distorted = any(intr.dist)
        m = self.MARGIN if distorted else 0
        size = (intr.width + 2 * m, intr.height + 2 * m)
        shift = np.array([[1.0, 0, m], [0, 1.0, m], [0, 0, 1.0]])
        h = shift @ ground_homography(intr, pose, self.camera_offset)
        gsd = max(pose[2], 0.05) / intr.fx
        g_res, g_img = _pick_level(self._ground, gsd)
        img = cv2.warpPerspective(
            g_img,
            h @ texture_affine(g_res, self._ground_side),
            size,
            flags=cv2.INTER_LINEAR,
            borderMode=cv2.BORDER_REFLECT,
        )
        p_res, p_img = _pick_level(self._pad, gsd)
        cv2.warpPerspective(
            p_img,
            h @ texture_affine(p_res, p_img.shape[0] * p_res),
            size,
            dst=img,
            flags=cv2.INTER_LINEAR,
            borderMode=cv2.BORDER_TRANSPARENT,
        )
        return self._apply_effects(img, m)

    def _apply_effects(self, img: np.ndarray, margin: int) -> np.ndarray:
        fx = self.effects
        if fx.exposure != 1.0:
            img = cv2.convertScaleAbs(img, alpha=fx.exposure)
        if fx.glare is not None:
            img = cv2.add(img, self._glare(img.shape, margin))
        if fx.blur_px >= 1.0:
            img = cv2.filter2D(img, -1, _line_kernel(fx.blur_px, fx.blur_angle_deg))
        if margin:
            mx, my = self._distortion_maps(margin)
            img = cv2.remap(img, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
        if fx.noise_sigma > 0:
            bank = self._noise_bank(img.shape)
            img = cv2.add(img, bank[int(self._rng.integers(len(bank)))], dtype=cv2.CV_8U)
        return img

    def _noise_bank(self, shape) -> list[np.ndarray]:
        """A few seeded Gaussian noise frames, drawn from at random (fast per-frame noise)."""
        key = (shape, self.effects.noise_sigma)
        if getattr(self, "_bank_key", None) != key:
            sigma = self.effects.noise_sigma
            self._bank = [
                np.round(self._rng.normal(0.0, sigma, shape)).astype(np.int16) for _ in range(6)
            ]
            self._bank_key = key
        return self._bank

    def _glare(self, shape, margin: int) -> np.ndarray:
        if self._glare_img is None or self._glare_img.shape != shape:
            g = self.effects.glare
            assert g is not None
            ys, xs = np.mgrid[0 : shape[0], 0 : shape[1]].astype(np.float32)
            d2 = (xs - g.x - margin) ** 2 + (ys - g.y - margin) ** 2
            blob = g.strength * np.exp(-d2 / (2 * g.radius**2))
            self._glare_img = np.repeat(blob[..., None], 3, axis=2).astype(np.uint8)
        return self._glare_img

    def _distortion_maps(self, margin: int) -> tuple[np.ndarray, np.ndarray]:
        if self._maps is None:
            intr = self.intrinsics
            k = intr.matrix()
            ys, xs = np.mgrid[0 : intr.height, 0 : intr.width].astype(np.float64)
            pts = np.column_stack((xs.ravel(), ys.ravel())).reshape(-1, 1, 2)
            ideal = cv2.undistortPoints(pts, k, np.asarray(intr.dist), P=k).reshape(-1, 2)
            mx = (ideal[:, 0] + margin).reshape(intr.height, intr.width).astype(np.float32)
            my = (ideal[:, 1] + margin).reshape(intr.height, intr.width).astype(np.float32)
            self._maps = (mx, my)
        return self._maps


def _line_kernel(length: float, angle_deg: float) -> np.ndarray:
    """A normalised motion-blur kernel: a line of `length` pixels at `angle_deg`."""
    size = math.ceil(length) | 1
    k = np.zeros((size, size), dtype=np.float32)
    c = size // 2
    dx, dy = math.cos(math.radians(angle_deg)), math.sin(math.radians(angle_deg))
    half = (length - 1) / 2
    p0 = (round((c - dx * half) * 16), round((c - dy * half) * 16))
    p1 = (round((c + dx * half) * 16), round((c + dy * half) * 16))
    cv2.line(k, p0, p1, 1.0, 1, cv2.LINE_AA, 4)
    return k / k.sum()
