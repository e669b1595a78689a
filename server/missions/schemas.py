"""API shapes of missions."""

from __future__ import annotations

import uuid
from typing import Annotated, Any, Literal

from pydantic import BaseModel, ConfigDict, Field

from server.kit.types import Name, Text, Timestamp
from server.missions.items import MissionItem
from server.missions.models import MissionKind

MAX_ITEMS_IN = 5000
MAX_RING_POINTS = 1000


class HomeIn(BaseModel):
    """Home (the landing base): lat, lon in degrees, alt in metres above mean sea level."""

    model_config = ConfigDict(extra="forbid", allow_inf_nan=False)
    lat: float
    lon: float
    alt: float = Field(default=0.0, ge=-1000, le=10000)


class Polygon(BaseModel):
    """A GeoJSON Polygon: rings of [lon, lat] positions; the first ring is the area (no holes)."""

    model_config = ConfigDict(extra="forbid", allow_inf_nan=False)
    type: Literal["Polygon"]
    coordinates: list[Annotated[list[list[float]], Field(max_length=MAX_RING_POINTS)]] = Field(
        max_length=10,
        description=f"[[[lon, lat], ...]]; at most {MAX_RING_POINTS} positions a ring",
    )


class CameraIn(BaseModel):
    """A camera; its footprint follows from the altitude."""

    model_config = ConfigDict(extra="forbid", allow_inf_nan=False)
    sensor_width_mm: float = Field(gt=0, le=100)
    sensor_height_mm: float = Field(gt=0, le=100)
    focal_length_mm: float = Field(gt=0, le=1000)
    image_width_px: int = Field(ge=1, le=100_000)
    image_height_px: int = Field(ge=1, le=100_000)


class FootprintIn(BaseModel):
    """A ground footprint given directly: across the flight line and along it, in metres."""

    model_config = ConfigDict(extra="forbid", allow_inf_nan=False)
    width_m: float = Field(gt=0, le=10_000, description="across the flight line")
    height_m: float = Field(gt=0, le=10_000, description="along the flight line")


class SurveyIn(BaseModel):
    """A survey area and how to photograph it; compiled into a lawnmower path."""

    model_config = ConfigDict(extra="forbid", allow_inf_nan=False)
    polygon: Polygon
    camera: CameraIn | None = None
    footprint: FootprintIn | None = None
    front_overlap_pct: float = Field(default=70.0, ge=0, le=95)
    side_overlap_pct: float = Field(default=60.0, ge=0, le=95)
    altitude_m: float = Field(description="metres above home")
    speed_mps: float = Field(default=5.0, gt=0, le=30)
    camera_trigger: bool = Field(
        default=True, description="DO_SET_CAM_TRIGG_DIST on each line; false: waypoints only"
    )
    heading_deg: float | None = Field(
        default=None,
        ge=-360,
        le=360,
        description="direction of the lines, clockwise from north; "
        "null: the one needing fewest lines",
    )


class MissionCreate(BaseModel):
    """A new mission: `items` for waypoints, `survey` for a survey."""

    model_config = ConfigDict(extra="forbid", allow_inf_nan=False)
    name: Name
    description: Text = ""
    kind: MissionKind = MissionKind.waypoints
    items: list[MissionItem] | None = Field(default=None, max_length=MAX_ITEMS_IN)
    survey: SurveyIn | None = None
    home: HomeIn | None = None
    speed_mps: float | None = Field(
        default=None, gt=0, le=30, description="cruise speed; null: the UAV's"
    )


class MissionUpdate(BaseModel):
    """Changes to a mission; a survey is compiled again when its area or parameters change."""

    model_config = ConfigDict(extra="forbid", allow_inf_nan=False)
    name: Name | None = None
    description: Text | None = None
    items: list[MissionItem] | None = Field(default=None, max_length=MAX_ITEMS_IN)
    survey: SurveyIn | None = None
    home: HomeIn | None = None
    speed_mps: float | None = Field(default=None, gt=0, le=30)


class SurveyPlanOut(BaseModel):
    """Figures of a compiled survey."""

    heading_deg: float
    line_count: int
    line_spacing_m: float
    trigger_distance_m: float
    footprint_width_m: float
    footprint_height_m: float
    gsd_cm: float | None
    area_m2: float


class EstimateOut(BaseModel):
    """Path length and flight time (at the mission's speed, else 8 m/s)."""

    distance_m: float
    flight_time_s: float
    endless: bool
    note: str


class MissionOut(BaseModel):
    """A mission."""

    id: uuid.UUID
    organization_id: uuid.UUID
    name: str
    description: str
    kind: MissionKind
    source: str = Field(description="api, qgc or wpl: how it was created")
    items: list[MissionItem]
    home: HomeIn | None
    speed_mps: float | None
    survey: dict[str, Any] | None
    survey_plan: SurveyPlanOut | None
    extras: dict[str, Any] = Field(
        description="QGroundControl geoFence / rallyPoints, carried through"
    )
    estimate: EstimateOut
    created_at: Timestamp
    updated_at: Timestamp


class ValidateRequest(BaseModel):
    """Check a mission, optionally against one UAV's endurance and a base's airspace."""

    model_config = ConfigDict(extra="forbid")
    uav_id: uuid.UUID | None = None
    base_id: uuid.UUID | None = Field(
        default=None,
        description="the base it would fly from: the flight starts and ends at its position "
        "(attributes latitude/longitude; unknown: the mission's home) and its own zones "
        "(operating area) apply too; the organisation's zones and the plan's geoFence apply always",
    )
    at: Timestamp | None = Field(
        default=None, description="when it would fly (zones' time windows); null: now"
    )


class UavLimitsOut(BaseModel):
    """The UAV figures a check used."""

    id: uuid.UUID
    name: str
    endurance_s: float
    usable_endurance_s: float
    cruise_speed_mps: float
    reach_m: float = Field(
        description="how far from the base an item may be: out and back within the usable "
        "endurance at the mission's speed (and within half the usable range), metres"
    )


class BaseCheckOut(BaseModel):
    """The base a check flew the mission from."""

    id: uuid.UUID
    name: str
    lat: float | None = Field(
        description="the base's latitude; null: unknown (mission's home used)"
    )
    lon: float | None = Field(description="the base's longitude; null: unknown")
    farthest_m: float | None = Field(
        description="the distance from the base of the item flown to farthest from it, metres; "
        "null when the base's position is unknown"
    )


class ValidationReport(BaseModel):
    """The outcome of a check: `valid`, one problem per fault, the estimate it used."""

    valid: bool
    problems: list[dict[str, Any]]
    estimate: EstimateOut = Field(
        description="the flight as checked: from the base and back when `base_id` locates one"
    )
    uav: UavLimitsOut | None
    base: BaseCheckOut | None = Field(description="the base checked from; null without `base_id`")
