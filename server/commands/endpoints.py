"""HTTP routes of commands to assets."""

from __future__ import annotations

import uuid
from typing import Annotated

from fastapi import APIRouter, Depends

from server.commands.schemas import CommandCreate, CommandOut, StatusChangeOut
from server.commands.service import CommandService
from server.deps import Operator, ServicesDep, UoW, Viewer
from server.kit.paging import PAGED, Pager, pager

router = APIRouter(tags=["commands"])


def _service(uow: UoW, principal: Viewer, services: ServicesDep) -> CommandService:
    return CommandService(uow, principal, services.broker)


def _operator_service(uow: UoW, principal: Operator, services: ServicesDep) -> CommandService:
    return CommandService(uow, principal, services.broker)


Commands = Annotated[CommandService, Depends(_service)]
CommandsOperator = Annotated[CommandService, Depends(_operator_service)]


@router.post("/api/v1/assets/{asset_id}/commands", status_code=202, response_model=CommandOut)
async def send_command(
    asset_id: uuid.UUID, body: CommandCreate, commands: CommandsOperator
) -> CommandOut:
    """Queue a command; it reaches the asset through whichever server process holds its socket."""
    cmd = await commands.send(asset_id, body.name, body.params, body.timeout_s)
    return CommandOut.model_validate(cmd)


@router.get("/api/v1/assets/{asset_id}/commands", response_model=list[CommandOut], responses=PAGED)
async def list_commands(
    asset_id: uuid.UUID,
    commands: Commands,
    pages: Annotated[Pager, Depends(pager(default=50, maximum=500))],
) -> list[CommandOut]:
    """The newest commands of an asset."""
    found = await commands.of_asset(asset_id, pages.page)
    pages.respond(found.total)
    return [CommandOut.model_validate(c) for c in found.items]


@router.get("/api/v1/commands/{command_id}", response_model=CommandOut)
async def get_command(command_id: uuid.UUID, commands: Commands) -> CommandOut:
    """A command with its status history."""
    cmd, history = await commands.with_history(command_id)
    out = CommandOut.model_validate(cmd)
    out.history = [StatusChangeOut.model_validate(h) for h in history]
    return out
