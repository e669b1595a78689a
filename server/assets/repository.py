"""All SQL of assets."""

from __future__ import annotations

import uuid
from collections.abc import Collection

from sqlalchemy import exists, or_, select
from sqlalchemy.ext.asyncio import AsyncSession

from server.assets.models import Asset
from server.kit.db import delete_unless_referred
from server.kit.errors import Conflict
from server.kit.paging import Page, Paged, paginate
from server.kit.scope import ScopedRepository
from server.runs.models import Run


class AssetRepository(ScopedRepository[Asset]):
    """Assets of the caller's organisation."""

    model = Asset
    noun = "asset"

    async def name_taken(self, name: str) -> bool:
        """True when any organisation already uses this name (names are global)."""
        stmt = select(Asset.id).where(Asset.name == name)  # unscoped: global uniqueness check only
        return (await self.db.execute(stmt)).first() is not None

    async def list_filtered(self, page: Page, kind: str | None) -> Paged[Asset]:
        """Assets of the caller's organisation, oldest first, optionally of one kind."""
        stmt = self.select().order_by(Asset.created_at, Asset.id)
        if kind:
            stmt = stmt.where(Asset.kind == kind)
        return await paginate(self.db, stmt, page)

    async def delete(self, asset: Asset) -> None:
        """Delete an asset in the current unit of work; Conflict while runs refer to it, as UAV
        or base: a run's report names both (`delete_unless_referred`)."""
        asset_id = asset.id
        in_use = Conflict(
            f"asset {asset_id} has flown runs (their reports refer to it) and cannot be deleted",
            code="asset_in_use",
        )
        by_id = or_(Run.uav_id == asset_id, Run.base_id == asset_id)
        flown = select(exists().where(by_id))  # unscoped: runs by its id
        await delete_unless_referred(self.db, asset, flown, in_use)

    async def bound_to(self, base_id: uuid.UUID) -> list[Asset]:
        """The UAVs bound to a landing base."""
        return list(
            (await self.db.execute(self.select().where(Asset.base_id == base_id))).scalars()
        )

    async def visible_ids(self, ids: Collection[uuid.UUID]) -> set[uuid.UUID]:
        """Which of these ids are assets of the caller's organisation (one query)."""
        if not ids:
            return set()
        stmt = self.select().with_only_columns(Asset.id).where(Asset.id.in_(list(ids)))
        return set((await self.db.execute(stmt)).scalars())

    @staticmethod
    async def by_name_for_login(db: AsyncSession, name: str) -> Asset | None:
        """The asset with this name, locked for the login's transaction (before any caller)."""
        stmt = (
            select(Asset).where(Asset.name == name).with_for_update()
        )  # unscoped: identity lookup
        return (await db.execute(stmt)).scalar_one_or_none()
