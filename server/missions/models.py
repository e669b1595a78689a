"""Table of missions."""

from __future__ import annotations

import enum
import uuid
from datetime import datetime
from typing import Any

from sqlalchemy import JSON, Enum, Float, ForeignKey, String
from sqlalchemy.orm import Mapped, mapped_column

from server.kit.db import Base, IdMixin
from server.kit.etag import Versioned
from server.kit.time import utcnow


class MissionKind(enum.StrEnum):
    """A list of waypoints, or a survey area compiled into a lawnmower path."""

    waypoints = "waypoints"
    survey = "survey"


class Mission(IdMixin, Versioned, Base):
    """A mission of one organisation: its items (MISSION_ITEM_INT shape) and, for a survey, its area."""

    __tablename__ = "missions"

    organization_id: Mapped[uuid.UUID] = mapped_column(
        ForeignKey("organizations.id", ondelete="CASCADE"), index=True
    )
    name: Mapped[str] = mapped_column(String(100))
    description: Mapped[str] = mapped_column(String(2000), default="")
    kind: Mapped[MissionKind] = mapped_column(
        Enum(MissionKind, name="mission_kind", native_enum=False, length=16)
    )
    source: Mapped[str] = mapped_column(String(16), default="api")  # api | qgc | wpl
    items: Mapped[list[dict[str, Any]]] = mapped_column(JSON, default=list)
    home: Mapped[dict[str, Any] | None] = mapped_column(JSON, default=None)
    speed_mps: Mapped[float | None] = mapped_column(Float, default=None)
    survey: Mapped[dict[str, Any] | None] = mapped_column(JSON, default=None)  # the area as given
    survey_plan: Mapped[dict[str, Any] | None] = mapped_column(
        JSON, default=None
    )  # compiled figures
    extras: Mapped[dict[str, Any]] = mapped_column(JSON, default=dict)  # QGC geoFence / rallyPoints
    created_by: Mapped[str | None] = mapped_column(String(64), default=None)
    created_at: Mapped[datetime] = mapped_column(default=utcnow)
    updated_at: Mapped[datetime] = mapped_column(default=utcnow, onupdate=utcnow)
