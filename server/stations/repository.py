"""All SQL of the landing-base domain."""

from __future__ import annotations

from sqlalchemy import select
from sqlalchemy.ext.asyncio import AsyncSession

from server.assets.models import Asset, AssetKind


async def all_bases(db: AsyncSession) -> list[Asset]:
    """Every landing base of every organisation (the NTRIP caster filters by organisation)."""
    stmt = (
        select(Asset).where(Asset.kind == AssetKind.landing_base).order_by(Asset.name)
    )  # unscoped: caster filters per caller
    return list((await db.execute(stmt)).scalars())
