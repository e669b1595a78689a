"""HTTP routes of assets and their configuration files."""

from __future__ import annotations

import base64
import uuid

from fastapi import APIRouter, Query, Request, Response

from server.assets.models import AssetKind
from server.assets.repository import AssetRepository
from server.assets.schemas import AssetCreate, AssetCreated, AssetOut, AssetUpdate, ConfigRequest
from server.assets.service import AssetService
from server.audit.service import record
from server.auth.service import SessionService
from server.deps import DB, Admin, SettingsDep, Viewer, client_addr, get_services
from server.kit.download import attachment

router = APIRouter(tags=["assets"])


def _service(db: DB, principal: Admin, settings: SettingsDep) -> AssetService:
    return AssetService(
        AssetRepository(db, principal), settings.effective_public_url, settings.config_scrypt_log_n
    )


async def _end_sessions(
    request: Request, db: DB, settings: SettingsDep, asset_id: uuid.UUID, reason: str
) -> None:
    ended = await SessionService(db, settings).end_all_for_asset(asset_id, reason)
    await db.commit()
    for listener in get_services(request).session_end_listeners:
        await listener(ended)


@router.get("/api/v1/assets", response_model=list[AssetOut])
async def list_assets(
    principal: Viewer,
    db: DB,
    kind: AssetKind | None = None,
    limit: int = Query(100, ge=1, le=1000),
    offset: int = Query(0, ge=0, le=10**9),
) -> list[AssetOut]:
    """Assets of the caller's organisation."""
    rows = await AssetRepository(db, principal).list_filtered(limit, offset, kind)
    return [AssetOut.model_validate(a) for a in rows]


@router.post("/api/v1/assets", status_code=201, response_model=AssetCreated)
async def create_asset(
    body: AssetCreate, principal: Admin, request: Request, db: DB, settings: SettingsDep
) -> AssetCreated:
    """Register an asset; answers with its encrypted configuration file (admins only)."""
    service = _service(db, principal, settings)
    asset, data = await service.register(
        name=body.name,
        kind=body.kind,
        password=body.password,
        description=body.description,
        base_id=body.base_id,
        attributes=body.attributes,
    )
    await record(
        db,
        "asset.created",
        organization_id=principal.organization_id,
        actor_kind="user",
        actor_id=principal.actor_id,
        target=str(asset.id),
        client_addr=client_addr(request),
        name=asset.name,
        kind=asset.kind.value,
    )
    out = AssetOut.model_validate(asset).model_dump()
    return AssetCreated(**out, config_file=base64.b64encode(data).decode())


@router.get("/api/v1/assets/{asset_id}", response_model=AssetOut)
async def get_asset(asset_id: uuid.UUID, principal: Viewer, db: DB) -> AssetOut:
    """One asset of the caller's organisation."""
    return AssetOut.model_validate(await AssetRepository(db, principal).get(asset_id))


@router.patch("/api/v1/assets/{asset_id}", response_model=AssetOut)
async def update_asset(
    asset_id: uuid.UUID,
    body: AssetUpdate,
    principal: Admin,
    request: Request,
    db: DB,
    settings: SettingsDep,
) -> AssetOut:
    """Rename an asset, describe it, bind a UAV to a base (admins only)."""
    service = _service(db, principal, settings)
    asset = await service.repo.get(asset_id)
    changes = body.model_dump(exclude_unset=True)
    await service.update(asset, changes)
    await record(
        db,
        "asset.updated",
        organization_id=principal.organization_id,
        actor_kind="user",
        actor_id=principal.actor_id,
        target=str(asset.id),
        client_addr=client_addr(request),
        changes=sorted(changes),
    )
    return AssetOut.model_validate(asset)


@router.delete("/api/v1/assets/{asset_id}", status_code=204, response_class=Response)
async def delete_asset(
    asset_id: uuid.UUID, principal: Admin, request: Request, db: DB, settings: SettingsDep
) -> Response:
    """Delete an asset and end its sessions (admins only)."""
    repo = AssetRepository(db, principal)
    asset = await repo.get(asset_id)
    await record(
        db,
        "asset.deleted",
        organization_id=principal.organization_id,
        actor_kind="user",
        actor_id=principal.actor_id,
        target=str(asset.id),
        client_addr=client_addr(request),
        name=asset.name,
    )
    await _end_sessions(request, db, settings, asset.id, "asset_deleted")
    await db.delete(asset)
    return Response(status_code=204)


@router.post(
    "/api/v1/assets/{asset_id}/config",
    response_class=Response,
    responses={
        200: {
            "content": {"application/octet-stream": {}},
            "description": "the encrypted configuration file",
        }
    },
)
async def reissue_config(
    asset_id: uuid.UUID,
    body: ConfigRequest,
    principal: Admin,
    request: Request,
    db: DB,
    settings: SettingsDep,
) -> Response:
    """Re-issue the configuration file with a new secret; the old secret stops working (admins only)."""
    service = _service(db, principal, settings)
    asset = await service.repo.get(asset_id)
    data = await service.reissue(asset, body.password)
    await record(
        db,
        "asset.credentials_rotated",
        organization_id=principal.organization_id,
        actor_kind="user",
        actor_id=principal.actor_id,
        target=str(asset.id),
        client_addr=client_addr(request),
    )
    await _end_sessions(request, db, settings, asset.id, "credentials_rotated")
    return Response(
        content=data,
        media_type="application/octet-stream",
        headers={"Content-Disposition": attachment(asset.name, ".abcf", default="asset")},
    )
