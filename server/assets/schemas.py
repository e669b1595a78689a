"""API shapes of assets."""

from __future__ import annotations

import uuid
from typing import Any

from pydantic import BaseModel, ConfigDict, Field

from server.assets.models import AssetKind
from server.kit.types import JsonObject, Name, Password, Text, Timestamp


class AssetCreate(BaseModel):
    """Registration of a UAV or a landing base; the password encrypts its config file."""

    model_config = ConfigDict(extra="forbid")
    name: Name
    kind: AssetKind
    password: Password
    description: Text = ""
    base_id: uuid.UUID | None = Field(
        default=None, description="for a UAV: the landing base it lives in"
    )
    attributes: JsonObject = Field(default_factory=dict, max_length=50)


class AssetUpdate(BaseModel):
    """Changes to an asset's description, base binding or attributes."""

    model_config = ConfigDict(extra="forbid")
    name: Name | None = None
    description: Text | None = None
    base_id: uuid.UUID | None = None
    attributes: JsonObject | None = Field(default=None, max_length=50)


class ConfigRequest(BaseModel):
    """The password for a re-issued configuration file."""

    model_config = ConfigDict(extra="forbid")
    password: Password


class AssetOut(BaseModel):
    """An asset."""

    model_config = ConfigDict(from_attributes=True)
    id: uuid.UUID
    organization_id: uuid.UUID
    name: str
    kind: AssetKind
    description: str
    base_id: uuid.UUID | None
    attributes: dict[str, Any]
    secret_rotated_at: Timestamp
    created_at: Timestamp
    updated_at: Timestamp


class AssetCreated(AssetOut):
    """A registered asset with its encrypted configuration file (base64)."""

    config_file: str = Field(description="the encrypted configuration file's bytes, base64")
