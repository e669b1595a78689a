"""Decisions about commands: creation, results from assets, deadlines."""

from __future__ import annotations

import uuid
from collections.abc import Mapping
from datetime import timedelta
from typing import Any

from pydantic import ValidationError
from sqlalchemy import select, update
from sqlalchemy.ext.asyncio import AsyncSession

from protocol import vocabulary
from protocol.vocabulary import FINAL_STATUSES, CommandParams
from server.assets.repository import AssetRepository
from server.commands.models import AssetCommand, CommandStatusChange
from server.commands.repository import CommandRepository
from server.kit import metrics
from server.kit.errors import Unprocessable
from server.kit.paging import Page, Paged
from server.kit.principal import Principal
from server.kit.service import Service
from server.kit.time import utcnow
from server.kit.uow import UnitOfWork
from server.realtime.broker import Broker
from server.realtime.channels import command_channel


def parse_command(name: str, params: Mapping[str, Any], kind: str) -> CommandParams:
    """The typed command of a request's name and params for an asset of `kind`; 422 naming the
    field when they do not fit, or the kinds it is for when an asset of `kind` does not answer it."""
    try:
        command = vocabulary.parse(name, params)
    except vocabulary.UnknownCommand as err:
        known = ", ".join(sorted(vocabulary.COMMANDS))
        raise Unprocessable(f"{err}; known: {known}", code="invalid_command") from err
    except ValidationError as err:
        raise Unprocessable(
            f"invalid params for {name}: {vocabulary.describe(err)}", code="invalid_command"
        ) from err
    wrong = vocabulary.wrong_kind(command, kind)
    if wrong:
        raise Unprocessable(wrong, code="invalid_command")
    return command


async def create(
    db: AsyncSession,
    *,
    organization_id: uuid.UUID,
    asset_id: uuid.UUID,
    command: CommandParams,
    timeout_s: float,
    created_by: str | None,
) -> AssetCommand:
    """A queued command with its deadline; its params are stored as they go on the wire."""
    now = utcnow()
    cmd = AssetCommand(
        organization_id=organization_id,
        asset_id=asset_id,
        name=command.name,
        params=vocabulary.params_of(command),
        status="queued",
        deadline=now + timedelta(seconds=timeout_s),
        created_by=created_by,
        created_at=now,
        updated_at=now,
    )
    db.add(cmd)
    await db.flush()
    db.add(CommandStatusChange(command_id=cmd.id, status="queued", at=now))
    await db.flush()
    return cmd


async def set_status(
    db: AsyncSession,
    cmd: AssetCommand,
    status: str,
    reason: str = "",
    progress: dict[str, Any] | None = None,
    result: dict[str, Any] | None = None,
) -> bool:
    """Move a command on; a final status is never left. Returns False when nothing changed.

    The database decides, not the object in hand: the update is conditional on the stored status
    not being final. A deadline sweep holding a command it read as in_progress cannot overwrite
    the `succeeded` an asset's result committed a moment later (it turned a finished
    check_availability into timed_out and aborted a run).
    """
    if cmd.status in FINAL_STATUSES:
        return False
    now = utcnow()
    values: dict[str, Any] = {"status": status, "reason": reason[:2000], "updated_at": now}
    if result is not None:
        values["result"] = result
    stmt = (
        update(AssetCommand)
        .where(AssetCommand.id == cmd.id, AssetCommand.status.not_in(list(FINAL_STATUSES)))
        .values(**values)
        .execution_options(synchronize_session=False)
    )
    changed = (await db.execute(stmt)).rowcount == 1  # type: ignore[attr-defined]
    await db.refresh(cmd)
    if not changed:
        return False
    db.add(
        CommandStatusChange(
            command_id=cmd.id, status=status, reason=reason[:2000], progress=progress, at=now
        )
    )
    await db.flush()
    if status in FINAL_STATUSES:
        metrics.COMMANDS.labels(cmd.name, status).inc()
        metrics.COMMAND_LATENCY.labels(cmd.name, status).observe(
            (now - cmd.created_at).total_seconds()
        )
    return True


async def apply_result(
    db: AsyncSession, command_id: uuid.UUID, asset_id: uuid.UUID, payload: dict[str, Any]
) -> bool:
    """Record a command_result from the asset the command was for."""
    cmd = await db.get(AssetCommand, command_id)
    if cmd is None or cmd.asset_id != asset_id:
        return False
    return await set_status(
        db,
        cmd,
        str(payload.get("status", "failed")),
        str(payload.get("reason", "")),
        payload.get("progress"),
        payload.get("data"),
    )


async def due_for_delivery(db: AsyncSession, asset_id: uuid.UUID) -> list[AssetCommand]:
    """Queued commands of an asset whose deadline has not passed, oldest first."""
    stmt = (
        select(AssetCommand)
        .where(  # unscoped: delivery to an authenticated asset's own socket
            AssetCommand.asset_id == asset_id,
            AssetCommand.status == "queued",
            AssetCommand.deadline > utcnow(),
        )
        .order_by(AssetCommand.created_at)
    )
    return list((await db.execute(stmt)).scalars())


async def assets_with_commands_due(db: AsyncSession, asset_ids: list[uuid.UUID]) -> set[uuid.UUID]:
    """Which of these assets have queued commands whose deadline has not passed (one query per
    500 assets)."""
    due: set[uuid.UUID] = set()
    now = utcnow()
    for start in range(0, len(asset_ids), 500):
        stmt = (
            select(AssetCommand.asset_id)
            .where(  # unscoped: delivery to authenticated assets' own sockets
                AssetCommand.asset_id.in_(asset_ids[start : start + 500]),
                AssetCommand.status == "queued",
                AssetCommand.deadline > now,
            )
            .distinct()
        )
        due.update((await db.execute(stmt)).scalars())
    return due


async def expire(db: AsyncSession) -> list[AssetCommand]:
    """Every unfinished command past its deadline becomes timed_out."""
    stmt = select(AssetCommand).where(  # unscoped: system sweep
        AssetCommand.status.not_in(list(FINAL_STATUSES)), AssetCommand.deadline <= utcnow()
    )
    expired = []
    for cmd in (await db.execute(stmt)).scalars():
        if await set_status(
            db,
            cmd,
            "timed_out",
            f"no final answer from the asset within its deadline ({cmd.deadline:%H:%M:%S} UTC)",
        ):
            expired.append(cmd)
    return expired


class CommandService(Service):
    """Commands of the caller's organisation: queue one, read them back."""

    def __init__(self, uow: UnitOfWork, principal: Principal, broker: Broker) -> None:
        super().__init__(uow, principal)
        self.broker = broker
        self.repo = CommandRepository(self.db, principal)
        self.assets = AssetRepository(self.db, principal)

    async def send(
        self, asset_id: uuid.UUID, name: str, params: Mapping[str, Any], timeout_s: float
    ) -> AssetCommand:
        """Queue a command; once it is committed, whichever process holds the asset's socket is
        nudged to deliver it (from the database)."""
        asset = await self.assets.get(asset_id)
        cmd = await create(
            self.db,
            organization_id=asset.organization_id,
            asset_id=asset.id,
            command=parse_command(name, params, asset.kind.value),
            timeout_s=timeout_s,
            created_by=self.principal.actor_id,
        )
        message = {"command_id": str(cmd.id)}

        async def nudge() -> None:
            await self.broker.publish(command_channel(asset.id), message)

        self.uow.after_commit(nudge)
        return cmd

    async def of_asset(self, asset_id: uuid.UUID, page: Page) -> Paged[AssetCommand]:
        """The newest commands of an asset of the caller's organisation."""
        await self.assets.get(asset_id)
        return await self.repo.of_asset(asset_id, page)

    async def with_history(
        self, command_id: uuid.UUID
    ) -> tuple[AssetCommand, list[CommandStatusChange]]:
        """A command and its status history."""
        cmd = await self.repo.get(command_id)
        return cmd, await self.repo.history(cmd.id)
