"""The downward camera as a part of the simulated world, with its control endpoints.

`world.add_part(CameraPart(pose_fn))` serves frames (see `sim.camera.server`) on an OS-chosen
port recorded in `world.ports["camera"]`; `pose_fn()` is the vehicle's true pose relative to the
pad centre, (north, east, up, roll, pitch, yaw), with `up` the camera's height above the pad.
Control: GET /camera (status) and PUT /camera/effects (exposure, glare, blur, noise) at run time.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from pydantic import BaseModel, Field

from sim.camera.render import CameraEffects, CameraIntrinsics, Glare, PadRenderer, Pose
from sim.camera.server import CameraServer


class EffectsIn(BaseModel):
    """Run-time image degradations (PUT /camera/effects)."""

    exposure: float = Field(default=1.0, gt=0.0, le=4.0)
    glare_x: float | None = None
    glare_y: float | None = None
    glare_radius: float = Field(default=60.0, gt=0.0)
    glare_strength: float = Field(default=120.0, ge=0.0, le=255.0)
    blur_px: float = Field(default=0.0, ge=0.0, le=50.0)
    blur_angle_deg: float = 0.0
    noise_sigma: float = Field(default=0.0, ge=0.0, le=50.0)

    def to_effects(self) -> CameraEffects:
        """The renderer's effects value."""
        glare = None
        if self.glare_x is not None and self.glare_y is not None:
            glare = Glare(self.glare_x, self.glare_y, self.glare_radius, self.glare_strength)
        return CameraEffects(
            self.exposure, glare, self.blur_px, self.blur_angle_deg, self.noise_sigma
        )


def camera_router(server: CameraServer) -> Any:
    """GET /camera and PUT /camera/effects for one camera server."""
    from fastapi import APIRouter

    router = APIRouter(prefix="/camera", tags=["camera"])

    @router.get("")
    def status() -> dict:
        """Port, rate, frames sent and the current effects."""
        fx = server.renderer.effects
        return {
            "port": server.port,
            "fps": server.fps,
            "frames_sent": server.frames_sent,
            "effects": {
                "exposure": fx.exposure,
                "blur_px": fx.blur_px,
                "noise_sigma": fx.noise_sigma,
                "glare": fx.glare is not None,
            },
        }

    @router.put("/effects")
    def set_effects(body: EffectsIn) -> dict:
        """Change the image degradations from the next frame on."""
        server.renderer.set_effects(body.to_effects())
        return {"ok": True}

    return router


class CameraPart:
    """Serves the simulated downward camera in the world."""

    name = "camera"

    def __init__(
        self,
        pose_fn: Callable[[], Pose],
        intrinsics: CameraIntrinsics | None = None,
        effects: CameraEffects | None = None,
        port: int = 0,
        fps: float = 30.0,
    ) -> None:
        self.pose_fn = pose_fn
        self.intrinsics = intrinsics
        self.effects = effects
        self.port = port
        self.fps = fps
        self.server: CameraServer | None = None

    async def start(self, world: Any) -> None:
        """Start serving on the world's clock; records `world.ports["camera"]`."""
        renderer = PadRenderer(self.intrinsics, self.effects, seed=world.config.seed)
        self.server = CameraServer(
            self.pose_fn, world.clock, renderer, world.config.host, self.port, self.fps
        )
        world.ports["camera"] = await self.server.start()

    def restart_stamps(self, at: float = 0.0) -> None:
        """The camera's capture timestamps count from `at` again."""
        if self.server is not None:
            self.server.restart_stamps(at)

    async def stop(self) -> None:
        """Stop serving."""
        if self.server is not None:
            await self.server.stop()

    def step(self, dt_sim: float) -> None:
        """Nothing to integrate: frames are rendered on their own schedule from `pose_fn`."""

    def routers(self) -> list[Any]:
        """The camera's control endpoints."""
        return [camera_router(self.server)] if self.server is not None else []
