"""The simulated camera's renderer: geometry, the optional effects, determinism."""

from __future__ import annotations

import numpy as np

from sim.camera.pad import pattern_points
from sim.camera.render import CameraEffects, CameraIntrinsics, Glare, PadRenderer, project_ground

POSE = (0.2, -0.1, 2.0, 0.05, -0.03, 0.6)


def bright_centroid(img, u, v, r=16):
    """Centroid of the bright pixels in a window around (u, v)."""
    win = img[int(v) - r : int(v) + r + 1, int(u) - r : int(u) + r + 1].min(axis=2).astype(float)
    ys, xs = np.nonzero(win > 128)
    return xs.mean() + int(u) - r, ys.mean() + int(v) - r


def test_frames_are_640x480_and_points_land_where_the_pinhole_model_puts_them():
    img = PadRenderer().render(POSE)
    assert img.shape == (480, 640, 3) and img.dtype == np.uint8
    ((u, v),) = project_ground(CameraIntrinsics(), POSE, np.array([pattern_points()["P1"]]))
    cu, cv = bright_centroid(img, u, v)
    assert abs(cu - u) < 0.3 and abs(cv - v) < 0.3


def test_lens_distortion_moves_points_as_opencv_projects_them():
    intr = CameraIntrinsics(dist=(-0.15, 0.04, 0.0, 0.0, 0.0))
    pose = (1.2, 1.0, 2.0, 0.0, 0.0, 0.0)
    img = PadRenderer(intr).render(pose)
    p1 = np.array([pattern_points()["P1"]])
    ((u, v),) = project_ground(intr, pose, p1)
    ((u0, v0),) = project_ground(CameraIntrinsics(), pose, p1)
    assert np.hypot(u - u0, v - v0) > 3  # distortion is visible at this radius
    cu, cv = bright_centroid(img, u, v)
    assert abs(cu - u) < 0.5 and abs(cv - v) < 0.5


def test_effects_exposure_glare_blur_noise():
    base = PadRenderer().render(POSE).astype(float)
    dark = PadRenderer(effects=CameraEffects(exposure=0.5)).render(POSE).astype(float)
    assert abs(dark.mean() - 0.5 * base.mean()) < 2
    glare = (
        PadRenderer(effects=CameraEffects(glare=Glare(100, 100, 40, 100)))
        .render(POSE)
        .astype(float)
    )
    assert (
        glare[100, 100].mean() - base[100, 100].mean() > 80
        and abs(glare[450, 600] - base[450, 600]).max() < 2
    )
    blur = (
        PadRenderer(effects=CameraEffects(blur_px=7, blur_angle_deg=0)).render(POSE).astype(float)
    )
    grad = lambda im: np.abs(np.diff(im, axis=1)).mean()  # noqa: E731
    assert grad(blur) < 0.8 * grad(base)
    a = PadRenderer(effects=CameraEffects(noise_sigma=5), seed=4).render(POSE).astype(float)
    b = PadRenderer(effects=CameraEffects(noise_sigma=5), seed=4).render(POSE).astype(float)
    assert np.array_equal(a, b)  # seeded
    mid = (base > 30) & (base < 220)
    assert 4 < (a - base)[mid].std() < 6


def test_effects_can_change_at_run_time():
    r = PadRenderer()
    before = r.render(POSE)
    r.set_effects(CameraEffects(exposure=0.3))
    assert r.render(POSE).mean() < 0.5 * before.mean()
