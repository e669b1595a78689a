"""The camera description of an asset (its `attributes.camera`) and the stream derived from it."""

from __future__ import annotations

from typing import Any, Literal

from pydantic import BaseModel, ConfigDict, Field, ValidationError

from server.kit.errors import Unprocessable


class CameraDescription(BaseModel):
    """What the asset's camera gives, hence what the stream will be (paper §2.2.2)."""

    model_config = ConfigDict(extra="ignore")
    width: int = Field(default=640, ge=16, le=7680)
    height: int = Field(default=480, ge=16, le=4320)
    fps: float = Field(default=30.0, gt=0, le=120)
    bitrate_kbps: int = Field(default=1000, ge=50, le=50_000)
    codec: Literal["vp8"] = "vp8"


def has_camera(attributes: dict[str, Any] | None) -> bool:
    """False for a UAV described as having no camera (`attributes.camera` false); a UAV with no
    description has the default camera."""
    return (attributes or {}).get("camera") is not False


def camera_of(attributes: dict[str, Any] | None) -> CameraDescription:
    """The asset's camera description (defaults when it has none); 422 when it is malformed."""
    raw = (attributes or {}).get("camera")
    if raw is None:
        raw = {}
    try:
        return CameraDescription.model_validate(raw)
    except ValidationError as err:
        raise Unprocessable(
            "the asset's attributes.camera is not a valid camera description",
            code="invalid_camera",
            details=[{"loc": [str(p) for p in e["loc"]], "msg": e["msg"]} for e in err.errors()],
        ) from err
