"""Decisions about assets: registration, credential files and secret rotation."""

from __future__ import annotations

import asyncio
import uuid
from typing import Any

from assetlink.configfile import AssetConfig, encrypt_config
from server.assets.models import Asset, AssetKind
from server.assets.repository import AssetRepository
from server.audit.service import record
from server.auth.service import SessionService
from server.config import Settings
from server.kit.errors import Conflict, Unprocessable
from server.kit.etag import NO_PRECONDITION, IfMatch
from server.kit.paging import Page, Paged
from server.kit.principal import Principal
from server.kit.security import new_secret, token_hash
from server.kit.service import Service
from server.kit.time import rfc3339, utcnow
from server.kit.uow import UnitOfWork


class AssetService(Service):
    """Registers assets, changes and deletes them, issues their encrypted configuration files."""

    def __init__(self, uow: UnitOfWork, principal: Principal, settings: Settings) -> None:
        super().__init__(uow, principal)
        self.settings = settings
        self.repo = AssetRepository(self.db, principal)
        self.server_url = settings.effective_public_url
        self.scrypt_log_n = settings.config_scrypt_log_n

    async def list_assets(self, page: Page, kind: AssetKind | None) -> Paged[Asset]:
        """Assets of the caller's organisation, optionally of one kind."""
        return await self.repo.list_filtered(page, kind)

    async def get(self, asset_id: uuid.UUID) -> Asset:
        """One asset of the caller's organisation (NotFound otherwise)."""
        return await self.repo.get(asset_id)

    async def _check_base(self, kind: AssetKind, base_id: uuid.UUID | None) -> None:
        if base_id is None:
            return
        if kind != AssetKind.uav:
            raise Unprocessable("only a UAV can be bound to a landing base", code="invalid_binding")
        base = await self.repo.get(base_id)  # NotFound for another organisation's base
        if base.kind != AssetKind.landing_base:
            raise Unprocessable(f"asset {base_id} is not a landing base", code="invalid_binding")

    async def register(
        self,
        *,
        name: str,
        kind: AssetKind,
        password: str,
        description: str,
        base_id: uuid.UUID | None,
        attributes: dict[str, Any],
    ) -> tuple[Asset, bytes]:
        """A new asset and its encrypted configuration file."""
        if await self.repo.name_taken(name):
            raise Conflict(f"an asset named {name!r} already exists", code="name_taken")
        await self._check_base(kind, base_id)
        asset = Asset(
            organization_id=self.repo.principal.organization_id,
            name=name,
            kind=kind,
            description=description,
            base_id=base_id,
            attributes=attributes,
            secret_hash="",
        )
        self.repo.db.add(asset)
        await self.repo.db.flush()
        data = await self._issue(asset, password)
        await record(
            self.uow,
            self.principal,
            "asset.created",
            target=str(asset.id),
            name=asset.name,
            kind=asset.kind.value,
        )
        return asset, data

    async def reissue(self, asset_id: uuid.UUID, password: str) -> tuple[Asset, bytes]:
        """A new configuration file with a new secret; the old secret and its sessions stop once
        this unit of work commits (and not at all if the answer cannot be built)."""
        asset = await self.repo.get(asset_id)
        data = await self._issue(asset, password)
        await record(self.uow, self.principal, "asset.credentials_rotated", target=str(asset.id))
        await SessionService(self.uow, self.settings).end_all_for_asset(
            asset.id, "credentials_rotated"
        )
        return asset, data

    async def delete(self, asset_id: uuid.UUID, expect: IfMatch = NO_PRECONDITION) -> None:
        """Delete an asset and end its sessions; the UAVs bound to a base are unbound. Conflict
        (409) for one that runs refer to: their reports keep it."""
        asset = await self.repo.get(asset_id, lock=True)
        expect.check(asset.version, f"asset {asset.id}")
        for uav in await self.repo.bound_to(asset.id):
            uav.base_id = None  # what ON DELETE SET NULL would do, through the ORM: a new version
        await record(
            self.uow, self.principal, "asset.deleted", target=str(asset.id), name=asset.name
        )
        await SessionService(self.uow, self.settings).end_all_for_asset(asset.id, "asset_deleted")
        await self.repo.delete(asset)

    async def _issue(self, asset: Asset, password: str) -> bytes:
        secret = new_secret()
        asset.secret_hash = token_hash(secret)
        asset.secret_rotated_at = utcnow()
        cfg = AssetConfig(
            server_url=self.server_url,
            asset_id=str(asset.id),
            name=asset.name,
            kind=asset.kind.value,
            secret=secret,
            issued_at=rfc3339(utcnow()),
        )
        # scrypt is deliberately slow: keep it off the event loop
        return await asyncio.to_thread(encrypt_config, cfg, password, self.scrypt_log_n)

    async def update(
        self, asset_id: uuid.UUID, changes: dict[str, Any], expect: IfMatch = NO_PRECONDITION
    ) -> Asset:
        """Apply a partial update (PreconditionFailed when `expect` names another version); a
        null leaves its field as it is, but for `base_id` (null: unbound from its base)."""
        asset = await self.repo.get(asset_id, lock=True)
        expect.check(asset.version, f"asset {asset.id}")
        changes = {k: v for k, v in changes.items() if v is not None or k == "base_id"}
        if "name" in changes and changes["name"] != asset.name:
            if await self.repo.name_taken(changes["name"]):
                raise Conflict(
                    f"an asset named {changes['name']!r} already exists", code="name_taken"
                )
        if "base_id" in changes:
            await self._check_base(asset.kind, changes["base_id"])
        for key, value in changes.items():
            setattr(asset, key, value)
        await self.repo.db.flush()
        await record(
            self.uow, self.principal, "asset.updated", target=str(asset.id), changes=sorted(changes)
        )
        return asset
