"""The landing pad exactly as the simulated camera renders it (paper §2.5.1), and its texture.

Pad frame: origin at the pad centre, x forward (the pad's symmetry axis, from P5 towards P1,
"north" when the pad's yaw is 0), y right ("east"), z down. All lengths in metres.

- Black velvet square of side PAD_SIDE.
- Masking frame: a reflective white square ring, outer side FRAME_OUTER, width FRAME_WIDTH.
- Custom pattern: P1, P2, P3 are the vertices of an equilateral triangle inscribed in a circle of
  diameter 75 cm centred on the pad, P1 on the +x axis. P4, P5, P6 are where a second circle — the
  triangle's incircle (radius R/2) — meets the triangle: the midpoints of P1P2, P2P3 and P3P1.
  P1 and P5 are white (the symmetry axis, hence the heading), P2, P3, P4, P6 red. Each point is a
  reflective disc of diameter POINT_DIAMETER.
- ArUco marker (DICT_4X4_50, id 0), side 10 cm, centred on the pad (where the centred downward
  camera still sees it once landed) on a white quiet zone of side ARUCO_QUIET.
"""

from __future__ import annotations

import math
from functools import lru_cache

import cv2
import numpy as np

PAD_SIDE = 1.2
FRAME_OUTER = 1.10
FRAME_WIDTH = 0.05
PATTERN_RADIUS = 0.375
POINT_DIAMETER = 0.10
ARUCO_SIZE = 0.10
ARUCO_QUIET = 0.14
ARUCO_CENTRE = (0.0, 0.0)
ARUCO_DICT = "DICT_4X4_50"
ARUCO_ID = 0
WHITE_POINTS = ("P1", "P5")

# reflective material: high Value on black (BGR)
BLACK_VELVET = (16, 16, 16)
WHITE_REFLECTIVE = (245, 245, 245)
RED_REFLECTIVE = (45, 40, 230)
PRINT_BLACK = (20, 20, 20)
PRINT_WHITE = (235, 235, 235)

TEXTURE_RES = 0.001  # metres per texel of the finest pad texture


def pattern_points(radius: float = PATTERN_RADIUS) -> dict[str, tuple[float, float]]:
    """The six pattern points P1..P6 as (x forward, y right) in the pad frame."""
    verts = {
        f"P{i + 1}": (radius * math.cos(a), radius * math.sin(a))
        for i, a in enumerate((0.0, 2 * math.pi / 3, -2 * math.pi / 3))
    }

    def mid(a: str, b: str) -> tuple[float, float]:
        return ((verts[a][0] + verts[b][0]) / 2, (verts[a][1] + verts[b][1]) / 2)

    return {**verts, "P4": mid("P1", "P2"), "P5": mid("P2", "P3"), "P6": mid("P3", "P1")}


def aruco_corners() -> np.ndarray:
    """The marker's four corners (x, y) in the pad frame, in OpenCV's order (TL, TR, BR, BL as seen
    in the texture: top = +x)."""
    cx, cy = ARUCO_CENTRE
    h = ARUCO_SIZE / 2
    return np.array(
        [(cx + h, cy - h), (cx + h, cy + h), (cx - h, cy + h), (cx - h, cy - h)], dtype=np.float64
    )


def texture_affine(res: float, side: float) -> np.ndarray:
    """3x3 map from texel (col, row, 1) to pad-frame ground (x, y, 1) for a square texture."""
    half = side / 2
    return np.array(
        [[0.0, -res, half - res / 2], [res, 0.0, res / 2 - half], [0.0, 0.0, 1.0]], dtype=np.float64
    )


def _to_texel(x: float, y: float, res: float, side: float) -> tuple[float, float]:
    half = side / 2
    return ((y + half) / res - 0.5, (half - x) / res - 0.5)


@lru_cache(maxsize=1)
def pad_texture_pyramid() -> tuple[tuple[float, np.ndarray], ...]:
    """The pad texture as (metres per texel, BGR image) levels, finest first (mip-mapping)."""
    res = TEXTURE_RES
    n = round(PAD_SIDE / res)
    img = np.full((n, n, 3), BLACK_VELVET, dtype=np.uint8)
    shift = 4
    scale = 1 << shift

    def px(x: float, y: float) -> tuple[int, int]:
        c, r = _to_texel(x, y, res, PAD_SIDE)
        return (round(c * scale), round(r * scale))

    def square(half: float, colour: tuple[int, int, int], cx: float = 0.0, cy: float = 0.0):
        c0, r0 = _to_texel(cx + half, cy - half, res, PAD_SIDE)
        c1, r1 = _to_texel(cx - half, cy + half, res, PAD_SIDE)
        img[round(r0 + 0.5) : round(r1 + 0.5), round(c0 + 0.5) : round(c1 + 0.5)] = colour

    square(FRAME_OUTER / 2, WHITE_REFLECTIVE)
    square(FRAME_OUTER / 2 - FRAME_WIDTH, BLACK_VELVET)
    for name, (x, y) in pattern_points().items():
        colour = WHITE_REFLECTIVE if name in WHITE_POINTS else RED_REFLECTIVE
        radius = round(POINT_DIAMETER / 2 / res * scale)
        cv2.circle(img, px(x, y), radius, colour, -1, cv2.LINE_AA, shift)
    square(ARUCO_QUIET / 2, PRINT_WHITE, *ARUCO_CENTRE)
    side_px = round(ARUCO_SIZE / res)
    dictionary = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, ARUCO_DICT))
    marker = cv2.aruco.generateImageMarker(dictionary, ARUCO_ID, side_px)
    c0, r0 = _to_texel(
        ARUCO_CENTRE[0] + ARUCO_SIZE / 2, ARUCO_CENTRE[1] - ARUCO_SIZE / 2, res, PAD_SIDE
    )
    c0, r0 = round(c0 + 0.5), round(r0 + 0.5)
    patch = np.where(marker[..., None] > 127, PRINT_WHITE, PRINT_BLACK).astype(np.uint8)
    img[r0 : r0 + side_px, c0 : c0 + side_px] = patch
    return _mip_levels(res, img)


@lru_cache(maxsize=4)
def ground_texture_pyramid(seed: int = 7, side: float = 40.0, res: float = 0.02):
    """A grass-and-gravel ground texture (with a few bright stones) as mip levels, finest first."""
    rng = np.random.default_rng(seed)
    n = round(side / res)
    base = np.zeros((n, n, 3), dtype=np.float32)
    for octave, weight in ((8, 0.5), (32, 0.3), (128, 0.2)):
        small = rng.random((octave, octave, 1)).astype(np.float32)
        base += weight * cv2.resize(small, (n, n), interpolation=cv2.INTER_CUBIC)[..., None]
    base += 0.25 * rng.random((n, n, 1)).astype(np.float32)
    colour = np.array([40, 95, 70], dtype=np.float32)  # greenish BGR
    img = np.clip(base * colour * 1.3, 0, 255).astype(np.uint8)
    for _ in range(int(side * side / 4)):
        c, r = rng.integers(0, n, size=2)
        v = int(rng.integers(150, 230))
        cv2.circle(img, (int(c), int(r)), int(rng.integers(1, 4)), (v, v, v), -1)
    return side, _mip_levels(res, img)


def _mip_levels(res: float, img: np.ndarray) -> tuple[tuple[float, np.ndarray], ...]:
    """Halve by box averaging while the size stays even (keeps texel centres aligned)."""
    levels = [(res, img)]
    while levels[-1][1].shape[0] % 2 == 0 and levels[-1][1].shape[0] > 64:
        prev_res, prev = levels[-1]
        half = prev.shape[0] // 2
        levels.append((prev_res * 2, cv2.resize(prev, (half, half), interpolation=cv2.INTER_AREA)))
    return tuple(levels)
