"""Table of airspace zones."""

from __future__ import annotations

import enum
import uuid
from datetime import datetime
from typing import Any

from sqlalchemy import JSON, Enum, Float, ForeignKey, String
from sqlalchemy.orm import Mapped, mapped_column

from server.kit.db import Base, IdMixin
from server.kit.time import utcnow


class ZoneKind(enum.StrEnum):
    """Where the UAV must stay (inclusion) or must never go (exclusion)."""

    inclusion = "inclusion"
    exclusion = "exclusion"


class AltitudeRef(enum.StrEnum):
    """What a zone's floor and ceiling are measured from."""

    base = "base"  # metres above the launch point (the base), as mission items are
    amsl = "amsl"  # metres above mean sea level


class AirspaceZone(IdMixin, Base):
    """A zone of one organisation: a GeoJSON Polygon, or a Point with `radius_m` (a circle).

    With `base_id` it is that base's own zone (its operating area) and applies only to flights
    from that base; without, it applies to every flight of the organisation.
    """

    __tablename__ = "airspace_zones"

    organization_id: Mapped[uuid.UUID] = mapped_column(
        ForeignKey("organizations.id", ondelete="CASCADE"), index=True
    )
    base_id: Mapped[uuid.UUID | None] = mapped_column(
        ForeignKey("assets.id", ondelete="CASCADE"), default=None, index=True
    )
    name: Mapped[str] = mapped_column(String(100))
    description: Mapped[str] = mapped_column(String(2000), default="")
    kind: Mapped[ZoneKind] = mapped_column(
        Enum(ZoneKind, name="zone_kind", native_enum=False, length=16)
    )
    geometry: Mapped[dict[str, Any]] = mapped_column(JSON)
    radius_m: Mapped[float | None] = mapped_column(Float, default=None)
    floor_m: Mapped[float | None] = mapped_column(Float, default=None)
    ceiling_m: Mapped[float | None] = mapped_column(Float, default=None)
    altitude_ref: Mapped[AltitudeRef] = mapped_column(
        Enum(AltitudeRef, name="altitude_ref", native_enum=False, length=8),
        default=AltitudeRef.base,
    )
    windows: Mapped[list[dict[str, Any]] | None] = mapped_column(JSON, default=None)
    created_by: Mapped[str | None] = mapped_column(String(64), default=None)
    created_at: Mapped[datetime] = mapped_column(default=utcnow)
    updated_at: Mapped[datetime] = mapped_column(default=utcnow, onupdate=utcnow)
