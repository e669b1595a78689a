"""The one place where organisation scoping happens.

Every readable query of an organisation-owned table starts from `scoped(Model, principal)`;
a test walks the repositories and fails on a raw `select(` of such a table. A row of another
organisation is therefore simply not found (404), never forbidden (403), so ids cannot be probed.
"""

from __future__ import annotations

import uuid
from typing import Any, Generic, TypeVar

from sqlalchemy import Select, false, select
from sqlalchemy.ext.asyncio import AsyncSession

from server.kit.errors import NotFound
from server.kit.paging import Page, Paged, paginate
from server.kit.principal import Principal

M = TypeVar("M")


def scoped(model: type[M], principal: Principal) -> Select[M]:
    """SELECT of `model` restricted to the principal's organisation (nothing without one)."""
    column: Any = model.organization_id  # type: ignore[attr-defined]
    if principal.organization_id is None:
        return select(model).where(false())
    return select(model).where(column == principal.organization_id)


class ScopedRepository(Generic[M]):
    """Base of repositories of organisation-owned tables: every read starts from `scoped`."""

    model: type[M]
    noun = "resource"

    def __init__(self, db: AsyncSession, principal: Principal) -> None:
        self.db = db
        self.principal = principal

    def select(self) -> Select[M]:
        """The scoped SELECT every query of this repository starts from."""
        return scoped(self.model, self.principal)

    async def get(self, id_: uuid.UUID, *, lock: bool = False) -> M:
        """The row with this id in the caller's organisation, else NotFound; `lock`: for the rest
        of the transaction, to edit it: FOR NO KEY UPDATE on PostgreSQL (rows referring to it may still
        be written: their foreign-key checks take KEY SHARE), none on SQLite."""
        stmt = self.select().where(self.model.id == id_)  # type: ignore[attr-defined]
        if lock:
            stmt = stmt.with_for_update(key_share=True).execution_options(populate_existing=True)
        row = (await self.db.execute(stmt)).scalar_one_or_none()
        if row is None:
            raise NotFound(f"{self.noun} {id_} not found")
        return row

    async def list(self, page: Page) -> Paged[M]:
        """Rows of the caller's organisation, oldest first, with their total."""
        model: Any = self.model
        return await paginate(self.db, self.select().order_by(model.created_at, model.id), page)
