"""Tables of telemetry samples, asset events and the durable streams' positions."""

from __future__ import annotations

import uuid
from datetime import datetime
from typing import Any

from sqlalchemy import JSON, BigInteger, ForeignKey, Index, Integer, String
from sqlalchemy.orm import Mapped, mapped_column

from server.kit.db import Base, IdMixin
from server.kit.time import utcnow


def sqlite_int() -> Integer:
    """SQLite auto-increments only an INTEGER primary key."""
    return Integer()


class TelemetrySample(Base):
    """One telemetry sample (the payload as JSON, nested as sent; rows written before issue 17
    hold it flattened, which reads the same), indexed by (asset, time)."""

    __tablename__ = "telemetry"
    __table_args__ = (
        # one index for both: time-range reads of an asset, and replays of a stream rewriting the
        # same (asset, ts, seq), stored once (a second index cost a second B-tree insert a row)
        Index("uq_telemetry_asset_ts_seq", "asset_id", "ts", "seq", unique=True),
    )

    id: Mapped[int] = mapped_column(
        BigInteger().with_variant(sqlite_int(), "sqlite"), primary_key=True, autoincrement=True
    )
    asset_id: Mapped[uuid.UUID] = mapped_column(ForeignKey("assets.id", ondelete="CASCADE"))
    ts: Mapped[datetime]
    seq: Mapped[int] = mapped_column(BigInteger)
    fields: Mapped[dict[str, Any]] = mapped_column(JSON)


class AssetEvent(IdMixin, Base):
    """An event an asset reported (or the server recorded about it)."""

    __tablename__ = "asset_events"
    __table_args__ = (Index("ix_asset_events_asset_ts", "asset_id", "ts"),)

    organization_id: Mapped[uuid.UUID] = mapped_column(
        ForeignKey("organizations.id", ondelete="CASCADE")
    )
    asset_id: Mapped[uuid.UUID] = mapped_column(ForeignKey("assets.id", ondelete="CASCADE"))
    ts: Mapped[datetime]
    name: Mapped[str] = mapped_column(String(200))
    severity: Mapped[str] = mapped_column(String(16))
    message: Mapped[str] = mapped_column(String(2000), default="")
    data: Mapped[dict[str, Any]] = mapped_column(JSON, default=dict)
    created_at: Mapped[datetime] = mapped_column(default=utcnow)


class AssetStream(Base):
    """How far the server has durably stored one sender's stream (for acks and de-duplication)."""

    __tablename__ = "asset_streams"

    stream_id: Mapped[uuid.UUID] = mapped_column(primary_key=True)
    asset_id: Mapped[uuid.UUID] = mapped_column(
        ForeignKey("assets.id", ondelete="CASCADE"), index=True
    )
    last_seq: Mapped[int] = mapped_column(BigInteger, default=0)
    updated_at: Mapped[datetime] = mapped_column(default=utcnow)
