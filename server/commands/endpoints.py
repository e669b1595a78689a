"""HTTP routes of commands to assets."""

from __future__ import annotations

import uuid
from datetime import datetime
from typing import Any

from fastapi import APIRouter, Query
from pydantic import BaseModel, ConfigDict, Field

from server.assets.repository import AssetRepository
from server.commands import service
from server.commands.repository import CommandRepository
from server.deps import DB, Operator, ServicesDep, Viewer
from server.kit.types import Name
from server.realtime.channels import command_channel

router = APIRouter(tags=["commands"])


class CommandCreate(BaseModel):
    """A command for an asset."""

    model_config = ConfigDict(extra="forbid")
    name: Name
    params: dict[str, Any] = Field(default_factory=dict, max_length=100)
    timeout_s: float = Field(default=60.0, gt=0, le=24 * 3600)


class StatusChangeOut(BaseModel):
    """One step of a command's history."""

    model_config = ConfigDict(from_attributes=True)
    at: datetime
    status: str
    reason: str
    progress: dict[str, Any] | None


class CommandOut(BaseModel):
    """A command and, when asked for one, its history."""

    model_config = ConfigDict(from_attributes=True)
    id: uuid.UUID
    asset_id: uuid.UUID
    name: str
    params: dict[str, Any]
    status: str
    reason: str
    result: dict[str, Any] | None
    deadline: datetime
    created_at: datetime
    updated_at: datetime
    history: list[StatusChangeOut] = []


@router.post("/api/v1/assets/{asset_id}/commands", status_code=202, response_model=CommandOut)
async def send_command(
    asset_id: uuid.UUID, body: CommandCreate, principal: Operator, services: ServicesDep, db: DB
) -> CommandOut:
    """Queue a command; it reaches the asset through whichever server process holds its socket."""
    asset = await AssetRepository(db, principal).get(asset_id)
    cmd = await service.create(
        db,
        organization_id=asset.organization_id,
        asset_id=asset.id,
        command=service.parse_command(body.name, body.params),
        timeout_s=body.timeout_s,
        created_by=principal.actor_id,
    )
    await db.commit()
    await services.broker.publish(command_channel(asset.id), {"command_id": str(cmd.id)})
    return CommandOut.model_validate(cmd)


@router.get("/api/v1/assets/{asset_id}/commands", response_model=list[CommandOut])
async def list_commands(
    asset_id: uuid.UUID, principal: Viewer, db: DB, limit: int = Query(50, ge=1, le=500)
) -> list[CommandOut]:
    """The newest commands of an asset."""
    await AssetRepository(db, principal).get(asset_id)
    return [
        CommandOut.model_validate(c)
        for c in await CommandRepository(db, principal).of_asset(asset_id, limit)
    ]


@router.get("/api/v1/commands/{command_id}", response_model=CommandOut)
async def get_command(command_id: uuid.UUID, principal: Viewer, db: DB) -> CommandOut:
    """A command with its status history."""
    repo = CommandRepository(db, principal)
    cmd = await repo.get(command_id)
    out = CommandOut.model_validate(cmd)
    out.history = [StatusChangeOut.model_validate(h) for h in await repo.history(cmd.id)]
    return out
