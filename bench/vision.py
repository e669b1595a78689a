"""Frames per second of the whole pad detector on 640x480 rendered frames, on one core, beside
OpenCV's ArUco detector alone on the same frames, and their ratio.

    python bench/vision.py [--frames N] [--repeat R] [--json]

Frames are rendered once (poses from 0.3 to 6 m, any yaw, tilt up to 15°, mild sensor noise);
only detection is timed. The whole detector does HSV, the masking frame, circle candidates,
K-means, pattern matching and ArUco; the reference is cv2.aruco.ArucoDetector.detectMarkers on
the grayscale frame. Prints a table and, with --json, one JSON object last. Never fails.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path

import cv2
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from asset_agent.precland.detect import PadDetector
from sim.camera.render import CameraEffects, PadRenderer


def render_frames(n: int, seed: int = 0) -> list[tuple[np.ndarray, float, float]]:
    """n frames (image, roll, pitch) spread over 0.3–6 m."""
    rng = np.random.default_rng(seed)
    renderer = PadRenderer(effects=CameraEffects(noise_sigma=2.0), seed=seed)
    frames = []
    for i in range(n):
        h = 0.3 + (6.0 - 0.3) * i / max(n - 1, 1)
        tilt, az = math.radians(15) * rng.random(), rng.uniform(0, 2 * math.pi)
        off, oa = 0.15 * h * rng.random(), rng.uniform(0, 2 * math.pi)
        pose = (
            off * math.cos(oa),
            off * math.sin(oa),
            h,
            tilt * math.cos(az),
            tilt * math.sin(az),
            rng.uniform(-math.pi, math.pi),
        )
        frames.append((renderer.render(pose), pose[3], pose[4]))
    return frames


def time_fps(fn, frames, repeat: int) -> float:
    """Frames per second of fn over the frames, best of `repeat` passes."""
    best = math.inf
    for _ in range(repeat):
        t0 = time.perf_counter()
        for f in frames:
            fn(f)
        best = min(best, time.perf_counter() - t0)
    return len(frames) / best


def main(argv: list[str] | None = None) -> int:
    """Run the benchmark and print its figures."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=120)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args(argv)
    cv2.setNumThreads(1)
    frames = render_frames(args.frames)
    detector = PadDetector()
    aruco = cv2.aruco.ArucoDetector(
        cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_4X4_50), cv2.aruco.DetectorParameters()
    )

    found = {"frame": 0, "pattern": 0, "aruco": 0}

    def whole(f):
        det = detector.detect(f[0], f[1], f[2])
        for k in found:
            found[k] += getattr(det, k) is not None

    def aruco_alone(f):
        aruco.detectMarkers(cv2.cvtColor(f[0], cv2.COLOR_BGR2GRAY))

    fps_whole = time_fps(whole, frames, args.repeat)
    fps_aruco = time_fps(aruco_alone, frames, args.repeat)
    ratio = fps_whole / fps_aruco
    rates = {k: v / (len(frames) * args.repeat) for k, v in found.items()}
    print(
        f"vision benchmark: {len(frames)} frames 640x480, 0.3-6 m, one core (cv2.setNumThreads(1))"
    )
    print(f"{'detector':<34}{'FPS':>8}{'ms/frame':>10}")
    print(f"{'whole (frame+pattern+ArUco)':<34}{fps_whole:>8.1f}{1000 / fps_whole:>10.2f}")
    print(f"{'OpenCV ArUco alone':<34}{fps_aruco:>8.1f}{1000 / fps_aruco:>10.2f}")
    print(
        f"ratio whole / ArUco alone: {ratio:.2f}   target whole >= 30 FPS: {'met' if fps_whole >= 30 else 'NOT met'}"
    )
    print("detection rate over the frames: " + ", ".join(f"{k} {v:.0%}" for k, v in rates.items()))
    if args.json:
        print(
            json.dumps(
                {
                    "frames": len(frames),
                    "fps_whole": round(fps_whole, 1),
                    "fps_aruco": round(fps_aruco, 1),
                    "ratio": round(ratio, 3),
                    "detection_rate": rates,
                    "target_fps": 30,
                    "target_met": fps_whole >= 30,
                }
            )
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
