"""All SQL of commands read through the API."""

from __future__ import annotations

import uuid

from sqlalchemy import select

from server.commands.models import AssetCommand, CommandStatusChange
from server.kit.paging import Page, Paged, paginate
from server.kit.scope import ScopedRepository


class CommandRepository(ScopedRepository[AssetCommand]):
    """Commands of the caller's organisation."""

    model = AssetCommand
    noun = "command"

    async def history(self, command_id: uuid.UUID) -> list[CommandStatusChange]:
        """Status changes of a command already resolved through `get`."""
        stmt = (
            select(CommandStatusChange)
            .where(
                CommandStatusChange.command_id == command_id
            )  # unscoped: command checked by get()
            .order_by(CommandStatusChange.at)
        )
        return list((await self.db.execute(stmt)).scalars())

    async def of_asset(self, asset_id: uuid.UUID, page: Page) -> Paged[AssetCommand]:
        """The newest commands of one asset."""
        stmt = (
            self.select()
            .where(AssetCommand.asset_id == asset_id)
            .order_by(AssetCommand.created_at.desc(), AssetCommand.id)
        )
        return await paginate(self.db, stmt, page)
