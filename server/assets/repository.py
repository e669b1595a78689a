"""All SQL of assets."""

from __future__ import annotations

import uuid
from collections.abc import Collection

from sqlalchemy import exists, or_, select, update
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
        """The asset with this name (before any caller; a login then holds it with
        `claim_for_login`)."""
        stmt = select(Asset).where(Asset.name == name)  # unscoped: identity lookup
        return (await db.execute(stmt)).scalar_one_or_none()

    @staticmethod
    async def claim_for_login(db: AsyncSession, asset_id: uuid.UUID, secret_hash: str) -> bool:
        """Hold the asset for a login's transaction on condition that its secret is still the
        one checked (False: rotated or deleted since). A write that changes nothing, not a
        SELECT … FOR UPDATE: on PostgreSQL it locks the row alike, and on SQLite (where FOR
        UPDATE is a plain read, outside any transaction) it takes the database's one writer, so
        a rotation or another login of the asset either waits for this transaction or is seen
        by what it reads next."""
        stmt = (
            update(Asset)  # unscoped: identity lookup, before any caller
            .where(Asset.id == asset_id, Asset.secret_hash == secret_hash)
            # the same values: no new version, no new `updated_at` (nothing was edited)
            .values(secret_hash=Asset.secret_hash, updated_at=Asset.updated_at)
            .execution_options(synchronize_session=False)
        )
        return bool((await db.execute(stmt)).rowcount == 1)  # type: ignore[attr-defined]
