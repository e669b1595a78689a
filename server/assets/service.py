"""Decisions about assets: registration, credential files and secret rotation."""

from __future__ import annotations

import asyncio
import uuid
from typing import Any

from assetlink.configfile import AssetConfig, encrypt_config
from server.assets.models import Asset, AssetKind
from server.assets.repository import AssetRepository
from server.kit.errors import Conflict, Unprocessable
from server.kit.security import new_secret, token_hash
from server.kit.time import utcnow


class AssetService:
    """Registers assets and issues their encrypted configuration files."""

    def __init__(self, repo: AssetRepository, server_url: str, scrypt_log_n: int) -> None:
        self.repo = repo
        self.server_url = server_url
        self.scrypt_log_n = scrypt_log_n

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
        return asset, await self._issue(asset, password)

    async def reissue(self, asset: Asset, password: str) -> bytes:
        """A new configuration file with a new secret; the old secret stops working."""
        return await self._issue(asset, password)

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
            issued_at=utcnow().isoformat(),
        )
        # scrypt is deliberately slow: keep it off the event loop
        return await asyncio.to_thread(encrypt_config, cfg, password, self.scrypt_log_n)

    async def update(self, asset: Asset, changes: dict[str, Any]) -> Asset:
        """Apply a partial update."""
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
        return asset
