"""HTTP routes of assets and their configuration files."""

from __future__ import annotations

import base64
import uuid
from typing import Annotated

from fastapi import APIRouter, Depends, Response

from server.assets.models import AssetKind
from server.assets.schemas import AssetCreate, AssetCreated, AssetOut, AssetUpdate, ConfigRequest
from server.assets.service import AssetService
from server.deps import Admin, SettingsDep, UoW, Viewer
from server.kit.download import attachment
from server.kit.errors import Conflict, NotFound
from server.kit.etag import CREATED_TAGGED, TAGGED, IfMatchDep, tag
from server.kit.openapi import errors
from server.kit.paging import PAGED, Paging

router = APIRouter(tags=["assets"])


def _service(uow: UoW, principal: Viewer, settings: SettingsDep) -> AssetService:
    return AssetService(uow, principal, settings)


def _admin_service(uow: UoW, principal: Admin, settings: SettingsDep) -> AssetService:
    return AssetService(uow, principal, settings)


Assets = Annotated[AssetService, Depends(_service)]
AssetsAdmin = Annotated[AssetService, Depends(_admin_service)]


@router.get("/api/v1/assets", response_model=list[AssetOut], responses=PAGED)
async def list_assets(
    assets: Assets, pages: Paging, kind: AssetKind | None = None
) -> list[AssetOut]:
    """Assets of the caller's organisation, oldest first."""
    found = await assets.list_assets(pages.page, kind)
    pages.respond(found.total)
    return [AssetOut.model_validate(a) for a in found.items]


@router.post(
    "/api/v1/assets",
    status_code=201,
    response_model=AssetCreated,
    responses={**CREATED_TAGGED, **errors(NotFound, Conflict)},  # base_id of no base; name taken
)
async def create_asset(body: AssetCreate, assets: AssetsAdmin, response: Response) -> AssetCreated:
    """Register an asset; answers with its encrypted configuration file (admins only)."""
    asset, data = await assets.register(
        name=body.name,
        kind=body.kind,
        password=body.password,
        description=body.description,
        base_id=body.base_id,
        attributes=body.attributes,
    )
    out = AssetOut.model_validate(asset).model_dump()
    tag(response, asset.version)
    return AssetCreated(**out, config_file=base64.b64encode(data).decode())


@router.get("/api/v1/assets/{asset_id}", response_model=AssetOut, responses=TAGGED)
async def get_asset(asset_id: uuid.UUID, assets: Assets, response: Response) -> AssetOut:
    """One asset of the caller's organisation, its ETag in the header."""
    asset = await assets.get(asset_id)
    tag(response, asset.version)
    return AssetOut.model_validate(asset)


@router.patch(
    "/api/v1/assets/{asset_id}",
    response_model=AssetOut,
    responses={**TAGGED, **errors(Conflict)},
)
async def update_asset(
    asset_id: uuid.UUID,
    body: AssetUpdate,
    assets: AssetsAdmin,
    expect: IfMatchDep,
    response: Response,
) -> AssetOut:
    """Rename an asset, describe it, bind a UAV to a base (admins only); with `If-Match`, only
    the version it names (else 412)."""
    asset = await assets.update(asset_id, body.model_dump(exclude_unset=True), expect)
    tag(response, asset.version)
    return AssetOut.model_validate(asset)


@router.delete(
    "/api/v1/assets/{asset_id}",
    status_code=204,
    response_class=Response,
    responses=errors(Conflict),  # 409: runs refer to it
)
async def delete_asset(asset_id: uuid.UUID, assets: AssetsAdmin, expect: IfMatchDep) -> Response:
    """Delete an asset and end its sessions (admins only); with `If-Match`, only the version it
    names (else 412)."""
    await assets.delete(asset_id, expect)
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
async def reissue_config(asset_id: uuid.UUID, body: ConfigRequest, assets: AssetsAdmin) -> Response:
    """Re-issue the configuration file with a new secret; the old secret stops working (admins only).

    The rotation commits only after this answer is built: if it cannot be, nothing rotates."""
    asset, data = await assets.reissue(asset_id, body.password)
    return Response(
        content=data,
        media_type="application/octet-stream",
        headers={"Content-Disposition": attachment(asset.name, ".abcf", default="asset")},
    )
