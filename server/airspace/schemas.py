"""API shapes of airspace zones: a zone is a GeoJSON geometry with properties."""

from __future__ import annotations

import uuid
from typing import Annotated, Any, Literal

from pydantic import BaseModel, ConfigDict, Field

from server.airspace.models import AltitudeRef, ZoneKind
from server.kit.types import Name, Text, Timestamp

MAX_ZONE_POINTS = 2000
MAX_RADIUS_M = 100_000.0
MAX_FEATURES = 500


class ZonePolygon(BaseModel):
    """A GeoJSON Polygon: one ring of [lon, lat] positions (holes are not supported)."""

    model_config = ConfigDict(extra="forbid", allow_inf_nan=False)
    type: Literal["Polygon"]
    coordinates: list[Annotated[list[list[float]], Field(max_length=MAX_ZONE_POINTS)]] = Field(
        min_length=1, max_length=1, description="[[[lon, lat], ...]]: one ring, no holes"
    )


class ZonePoint(BaseModel):
    """A GeoJSON Point: the centre of a circle whose radius is the zone's `radius_m`."""

    model_config = ConfigDict(extra="forbid", allow_inf_nan=False)
    type: Literal["Point"]
    coordinates: list[float] = Field(min_length=2, max_length=3, description="[lon, lat]")


Geometry = Annotated[ZonePolygon | ZonePoint, Field(discriminator="type")]


class TimeWindow(BaseModel):
    """A period in which the zone is active: [start, end)."""

    model_config = ConfigDict(extra="forbid")
    start: Timestamp
    end: Timestamp


class ZoneFields(BaseModel):
    """What a zone says besides its shape."""

    model_config = ConfigDict(extra="forbid", allow_inf_nan=False)
    name: Name
    description: Text = ""
    kind: ZoneKind
    radius_m: float | None = Field(
        default=None, gt=0, le=MAX_RADIUS_M, description="a circle's radius; Points only"
    )
    floor_m: float | None = Field(default=None, ge=-1000, le=20_000)
    ceiling_m: float | None = Field(
        default=None,
        ge=-1000,
        le=20_000,
        description="null: no ceiling; a base's inclusion zone defaults to 120 m above the base",
    )
    altitude_ref: AltitudeRef = Field(
        default=AltitudeRef.base, description="floor/ceiling above the base, or above sea level"
    )
    windows: list[TimeWindow] | None = Field(
        default=None, max_length=100, description="null: always active; else active in these"
    )
    base_id: uuid.UUID | None = Field(
        default=None, description="a base's own zone (its operating area): applies to its flights"
    )


class ZoneIn(ZoneFields):
    """A new zone."""

    geometry: Geometry


class ZoneUpdate(BaseModel):
    """Changes to a zone; the result is validated as a whole."""

    model_config = ConfigDict(extra="forbid", allow_inf_nan=False)
    name: Name | None = None
    description: Text | None = None
    kind: ZoneKind | None = None
    geometry: Geometry | None = None
    radius_m: float | None = Field(default=None, gt=0, le=MAX_RADIUS_M)
    floor_m: float | None = Field(default=None, ge=-1000, le=20_000)
    ceiling_m: float | None = Field(default=None, ge=-1000, le=20_000)
    altitude_ref: AltitudeRef | None = None
    windows: list[TimeWindow] | None = Field(default=None, max_length=100)


class ZoneOut(BaseModel):
    """A zone."""

    id: uuid.UUID
    organization_id: uuid.UUID
    base_id: uuid.UUID | None
    name: str
    description: str
    kind: ZoneKind
    geometry: dict[str, Any]
    radius_m: float | None
    floor_m: float | None
    ceiling_m: float | None
    altitude_ref: AltitudeRef
    windows: list[TimeWindow] | None
    active: bool = Field(description="active now (always, or inside one of its windows)")
    created_at: Timestamp
    updated_at: Timestamp


class FeatureCollectionIn(BaseModel):
    """A GeoJSON FeatureCollection: each Feature's properties are a zone's fields."""

    model_config = ConfigDict(extra="allow")
    type: Literal["FeatureCollection"]
    features: list[dict[str, Any]] = Field(max_length=MAX_FEATURES)
