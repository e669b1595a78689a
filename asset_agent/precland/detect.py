"""The pad detector of the paper (§2.5.2), element by element: masking frame, six-point pattern,
ArUco — each returning an `ElementPose` with a quality, or None.

Pipeline: HSV; the Value channel thresholded relative to its brightest pixels (robust to
exposure); the masking frame is a square contour whose hole is a square of the ring's side ratio;
its inside, eroded, masks the Value image (so lens flare on the ring and the ground's bright
stones are ignored); circle candidates are bright blobs that fill their enclosing circle (this
rejects the ArUco's square quiet zone); K-means splits them into two colour sets on (sin(hue),
saturation); the pattern is matched geometrically: each ordered white pair is taken as (P1, P5),
which fixes a similarity that predicts P2, P3, P4, P6 among the red set; the best full six-point
fit wins. ArUco runs on the (masked) Value image with OpenCV's ArucoDetector.

Each pose reports its uncertainty: the centre's angular 1-sigma is the attitude's error (the
levelling uses the autopilot's roll and pitch, wrong by the same angle for every point) and the
points' own error (the configured pixel sigma and the fit's residual, averaged over the points),
times the height.

Lens distortion is removed from the detected points rather than from the whole image: the same
geometry for a fraction of the cost (`geometry.level_normalised`), which also corrects attitude.
"""

from __future__ import annotations

import itertools
import logging
import math
from dataclasses import dataclass

import cv2
import numpy as np

from asset_agent.precland.config import CameraModel, DetectorConfig, PadGeometry
from asset_agent.precland.geometry import (
    ElementPose,
    Similarity,
    apply_similarity,
    fit_similarity,
    level_normalised,
    pose_from_similarity,
)

log = logging.getLogger(__name__)

PATTERN_ORDER = ("P1", "P5", "P2", "P3", "P4", "P6")


@dataclass(frozen=True)
class Detections:
    """What one frame gave, per element (None when the element was not found)."""

    frame: ElementPose | None
    pattern: ElementPose | None
    aruco: ElementPose | None
    candidates: int = 0


@dataclass(frozen=True)
class _Blob:
    x: float
    y: float
    sin_hue: float
    saturation: float


class PadDetector:
    """Detects the pad's three elements in BGR frames; stateless between frames."""

    def __init__(
        self,
        pad: PadGeometry | None = None,
        camera: CameraModel | None = None,
        config: DetectorConfig | None = None,
    ) -> None:
        self.pad = pad or PadGeometry()
        self.camera = camera or CameraModel()
        self.config = config or DetectorConfig()
        pts = self.pad.pattern_points()
        self._model = np.array([pts[k] for k in PATTERN_ORDER])
        self._axis = float(np.linalg.norm(self._model[0] - self._model[1]))
        dictionary = cv2.aruco.getPredefinedDictionary(
            getattr(cv2.aruco, self.pad.aruco_dictionary)
        )
        params = cv2.aruco.DetectorParameters()
        params.cornerRefinementMethod = cv2.aruco.CORNER_REFINE_SUBPIX
        self._aruco = cv2.aruco.ArucoDetector(dictionary, params)
        o = self.pad.frame_outer / 2
        self._frame_model = np.array([(o, -o), (o, o), (-o, o), (-o, -o)])

    def detect(self, image: np.ndarray, roll: float = 0.0, pitch: float = 0.0) -> Detections:
        """Run every enabled element on one BGR frame taken at the given roll and pitch."""
        cfg = self.config
        hsv = cv2.cvtColor(image, cv2.COLOR_BGR2HSV)
        value = hsv[:, :, 2]
        hist = cv2.calcHist([value], [0], None, [256], [0, 256]).ravel()
        cdf = np.cumsum(hist) / hist.sum()
        p999 = int(np.searchsorted(cdf, 0.999))
        thr = max(cfg.value_floor, int(cfg.value_fraction * p999))
        _, binary = cv2.threshold(value, thr, 255, cv2.THRESH_BINARY)
        if cfg.local_contrast > 0:
            binary = cv2.bitwise_and(binary, self._above_background(value))
        frame, mask = (None, None)
        if cfg.use_frame:
            frame, mask = self._masking_frame(binary, roll, pitch)
        if mask is not None:
            binary = cv2.bitwise_and(binary, mask)
        pattern, n = (None, 0)
        if cfg.use_pattern:
            pattern, n = self._pattern(binary, hsv, thr, roll, pitch)
        aruco = None
        if cfg.use_aruco:
            gray = value if mask is None else cv2.bitwise_and(value, mask)
            aruco = self._aruco_pose(gray, roll, pitch)
        return Detections(frame, pattern, aruco, n)

    def _above_background(self, value: np.ndarray) -> np.ndarray:
        """Pixels brighter than the local background by `local_contrast`: the background is a
        morphological opening on a coarse grid, so a smooth lens flare is background while the
        reflective elements (narrower than the kernel) are not."""
        cfg = self.config
        h, w = value.shape
        cell = cfg.background_cell_px
        small = cv2.resize(
            value, (max(1, w // cell), max(1, h // cell)), interpolation=cv2.INTER_AREA
        )
        k = cv2.getStructuringElement(cv2.MORPH_RECT, (cfg.background_kernel_cells,) * 2)
        bg = cv2.morphologyEx(small, cv2.MORPH_OPEN, k)
        bg = cv2.resize(cv2.blur(bg, (3, 3)), (w, h), interpolation=cv2.INTER_LINEAR)
        level = cv2.add(bg, np.full_like(bg, cfg.local_contrast))
        return cv2.compare(value, level, cv2.CMP_GT)

    # -- masking frame -------------------------------------------------------------------------

    def _masking_frame(self, binary: np.ndarray, roll: float, pitch: float):
        cfg = self.config
        contours, hierarchy = cv2.findContours(binary, cv2.RETR_CCOMP, cv2.CHAIN_APPROX_SIMPLE)
        if hierarchy is None:
            return None, None
        best = None
        for i, c in enumerate(contours):
            child = hierarchy[0][i][2]
            if hierarchy[0][i][3] != -1 or child < 0:
                continue
            outer = _square(c, cfg.min_frame_side_px)
            if outer is None:
                continue
            while child >= 0:  # any hole of the right shape and size
                inner = _square(contours[child], cfg.min_frame_side_px * 0.8)
                if inner is not None:
                    ratio = math.sqrt(cv2.contourArea(inner) / cv2.contourArea(outer))
                    lo, hi = cfg.frame_hole_ratio
                    if lo <= ratio <= hi and (best is None or cv2.contourArea(outer) > best[2]):
                        best = (outer, inner, cv2.contourArea(outer))
                child = hierarchy[0][child][0]
        if best is None:
            return None, None
        outer, inner, _ = best
        mask = np.zeros_like(binary)
        cv2.fillPoly(mask, [inner.astype(np.int32)], 255)
        side = math.sqrt(cv2.contourArea(inner))
        k = max(3, int(side * 0.03) | 1)
        mask = cv2.erode(mask, cv2.getStructuringElement(cv2.MORPH_RECT, (k, k)))
        pose = self._frame_pose(outer.reshape(-1, 2).astype(np.float64), roll, pitch)
        return pose, mask

    def _frame_pose(self, corners: np.ndarray, roll: float, pitch: float) -> ElementPose | None:
        q = level_normalised(corners, self.camera, roll, pitch)
        best = None
        for shift in range(4):  # the square's four-fold symmetry: keep the smallest rotation
            for order in (q, q[::-1]):
                sim = fit_similarity(self._frame_model, np.roll(order, shift, axis=0))
                if best is None or (sim.rms, abs(sim.angle)) < (best.rms, abs(best.angle)):
                    best = sim
        assert best is not None
        rel = best.rms / (best.scale * self.pad.frame_outer)
        if rel > 0.05:
            return None
        return pose_from_similarity("frame", best, max(0.0, 1.0 - rel / 0.05), heading=False)

    # -- six-point pattern ---------------------------------------------------------------------

    def _pattern(self, binary, hsv, thr: int, roll: float, pitch: float):
        blobs = self._circles(binary, hsv, thr)
        if len(blobs) < 6:
            return None, len(blobs)
        whites, reds = self._colour_sets(blobs)
        if len(whites) < 2 or len(reds) < 4:
            return None, len(blobs)
        w = level_normalised(np.array([(b.x, b.y) for b in whites]), self.camera, roll, pitch)
        r = level_normalised(np.array([(b.x, b.y) for b in reds]), self.camera, roll, pitch)
        return self._match(w, r), len(blobs)

    def _circles(self, binary: np.ndarray, hsv: np.ndarray, thr: int) -> list[_Blob]:
        cfg = self.config
        contours, _ = cv2.findContours(binary, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
        max_area = cfg.max_blob_area_fraction * binary.size
        blobs = []
        value = hsv[:, :, 2]
        for c in contours:
            area = cv2.contourArea(c) + 0.5 * len(c)  # pixel area, not the polygon's
            if area < cfg.min_blob_area_px or area > max_area:
                continue
            (_, _), radius = cv2.minEnclosingCircle(c)
            if area / (math.pi * (radius + 0.5) ** 2) < cfg.circle_fill_min:
                continue
            x0, y0, w, h = cv2.boundingRect(c)
            x0, y0 = max(0, x0 - 1), max(0, y0 - 1)
            roi = value[y0 : y0 + h + 2, x0 : x0 + w + 2].astype(np.float32)
            weight = np.clip(roi - thr * 0.5, 0, None)
            m = cv2.moments(weight)
            if m["m00"] <= 0:
                continue
            sel = roi >= thr
            hue = hsv[y0 : y0 + h + 2, x0 : x0 + w + 2, 0][sel].astype(np.float32)
            sat = hsv[y0 : y0 + h + 2, x0 : x0 + w + 2, 1][sel].astype(np.float32)
            if hue.size == 0:
                continue
            sin_hue = float(np.mean(np.sin(hue * (np.pi / 90.0))))
            blobs.append(
                _Blob(
                    x0 + m["m10"] / m["m00"],
                    y0 + m["m01"] / m["m00"],
                    sin_hue,
                    float(sat.mean()) / 255,
                )
            )
        return blobs

    def _colour_sets(self, blobs: list[_Blob]) -> tuple[list[_Blob], list[_Blob]]:
        feats = np.array([(b.sin_hue, b.saturation) for b in blobs], dtype=np.float32)
        criteria = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 20, 1e-3)
        # deterministic start: the least and the most saturated blob
        labels0 = (feats[:, 1] > (feats[:, 1].min() + feats[:, 1].max()) / 2).astype(np.int32)
        _, labels, centres = cv2.kmeans(
            feats, 2, labels0.reshape(-1, 1), criteria, 1, cv2.KMEANS_USE_INITIAL_LABELS
        )
        if abs(float(centres[0, 1] - centres[1, 1])) < self.config.min_saturation_gap:
            return [], []
        white_label = int(np.argmin(centres[:, 1]))
        labels = labels.ravel()
        whites = [b for b, lab in zip(blobs, labels, strict=True) if lab == white_label]
        reds = [b for b, lab in zip(blobs, labels, strict=True) if lab != white_label]
        return whites, reds

    def _match(self, whites: np.ndarray, reds: np.ndarray) -> ElementPose | None:
        cfg = self.config
        best = None
        for i, j in itertools.permutations(range(len(whites)), 2):
            pair = fit_similarity(self._model[:2], whites[[i, j]])
            axis_img = pair.scale * self._axis
            if axis_img <= 0:
                continue
            predicted = apply_similarity(pair, self._model[2:])
            d = np.linalg.norm(predicted[:, None, :] - reds[None, :, :], axis=2)
            pick = d.argmin(axis=1)
            if (
                len(set(pick.tolist())) < 4
                or d[np.arange(4), pick].max() > cfg.match_tolerance * axis_img
            ):
                continue
            observed = np.vstack((whites[[i, j]], reds[pick]))
            sim = fit_similarity(self._model, observed)
            rel = sim.rms / (sim.scale * self._axis)
            if rel <= cfg.max_residual and (best is None or rel < best[0]):
                best = (rel, sim)
        if best is None:
            return None
        rel, sim = best
        return pose_from_similarity(
            "pattern", sim, 1.0 - rel / cfg.max_residual, True, self._sigma_rad(sim, 6)
        )

    # -- ArUco ---------------------------------------------------------------------------------

    def _aruco_pose(self, gray: np.ndarray, roll: float, pitch: float) -> ElementPose | None:
        corners, ids, _ = self._aruco.detectMarkers(gray)
        if ids is None:
            return None
        for c, marker_id in zip(corners, ids.ravel(), strict=True):
            if int(marker_id) != self.pad.aruco_id:
                continue
            px = c.reshape(-1, 2)
            side = float(np.mean(np.linalg.norm(px - np.roll(px, 1, axis=0), axis=1)))
            if side < self.config.aruco_min_side_px:
                continue
            q = level_normalised(px, self.camera, roll, pitch)
            sim = fit_similarity(self.pad.aruco_corners(), q)
            rel = sim.rms / (sim.scale * self.pad.aruco_size)
            if rel > self.config.aruco_max_residual:
                continue
            return pose_from_similarity(
                "aruco",
                sim,
                1.0 - rel / self.config.aruco_max_residual,
                True,
                self._sigma_rad(sim, 4),
            )
        return None

    def _sigma_rad(self, sim: Similarity, points: int) -> float:
        """The centre's angular 1-sigma per axis: attitude error, and the points' pixel error and
        fit residual (level camera, focal length 1) averaged over `points`."""
        cfg = self.config
        pixel = cfg.pixel_sigma_px / self.camera.fx
        return math.sqrt(cfg.attitude_sigma_rad**2 + (pixel**2 + sim.rms**2) / points)


def _square(contour: np.ndarray, min_side: float) -> np.ndarray | None:
    """The 4 corners of a convex, roughly equal-sided quadrilateral contour, else None."""
    peri = cv2.arcLength(contour, True)
    if peri < 4 * min_side:
        return None
    approx = cv2.approxPolyDP(contour, 0.03 * peri, True)
    if len(approx) != 4 or not cv2.isContourConvex(approx):
        return None
    pts = approx.reshape(-1, 2).astype(np.float32)
    sides = np.linalg.norm(pts - np.roll(pts, 1, axis=0), axis=1)
    if sides.min() < 0.7 * sides.max():
        return None
    return pts
