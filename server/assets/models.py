"""Table of assets."""

from __future__ import annotations

import enum
import uuid
from datetime import datetime
from typing import Any

from sqlalchemy import JSON, Enum, ForeignKey, String
from sqlalchemy.orm import Mapped, mapped_column

from server.kit.db import Base, IdMixin
from server.kit.etag import Versioned
from server.kit.time import utcnow


class AssetKind(enum.StrEnum):
    """What an asset is."""

    uav = "uav"
    landing_base = "landing_base"


class Asset(IdMixin, Versioned, Base):
    """A UAV or a landing base, owned by one organisation; its name is globally unique."""

    __tablename__ = "assets"

    organization_id: Mapped[uuid.UUID] = mapped_column(
        ForeignKey("organizations.id", ondelete="CASCADE"), index=True
    )
    name: Mapped[str] = mapped_column(String(100), unique=True)
    kind: Mapped[AssetKind] = mapped_column(
        Enum(AssetKind, name="asset_kind", native_enum=False, length=16)
    )
    description: Mapped[str] = mapped_column(String(2000), default="")
    secret_hash: Mapped[str] = mapped_column(String(64))
    secret_rotated_at: Mapped[datetime] = mapped_column(default=utcnow)
    base_id: Mapped[uuid.UUID | None] = mapped_column(
        ForeignKey("assets.id", ondelete="SET NULL"), default=None
    )
    attributes: Mapped[dict[str, Any]] = mapped_column(JSON, default=dict)
    created_at: Mapped[datetime] = mapped_column(default=utcnow)
    updated_at: Mapped[datetime] = mapped_column(default=utcnow, onupdate=utcnow)
