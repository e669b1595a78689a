"""API shapes of login and sessions."""

from __future__ import annotations

import enum
import uuid

from pydantic import BaseModel, ConfigDict

from server.kit.principal import Role
from server.kit.types import Email, LoginPassword, Name, Password, Text, Timestamp


class PrincipalKind(enum.StrEnum):
    """Who holds a session: a person (`user`) or a machine (`asset`: a UAV or a landing base)."""

    user = "user"
    asset = "asset"


class PasswordChange(BaseModel):
    """The caller's current password and the one to replace it (12 characters or more)."""

    model_config = ConfigDict(extra="forbid")
    current_password: LoginPassword
    new_password: Password


class LoginRequest(BaseModel):
    """A user's credentials; `force` ends a live session instead of being refused."""

    model_config = ConfigDict(extra="forbid")
    email: Email
    password: LoginPassword
    force: bool = False
    organization_id: uuid.UUID | None = None


class AssetLoginRequest(BaseModel):
    """An asset's name and secret (from its configuration file)."""

    model_config = ConfigDict(extra="forbid")
    name: Name
    secret: Text
    force: bool = False


class TokenResponse(BaseModel):
    """An opaque bearer token."""

    access_token: str
    token_type: str = "bearer"
    expires_at: Timestamp
    session_id: uuid.UUID


class MembershipOut(BaseModel):
    """One organisation the user belongs to, and the role there."""

    organization_id: uuid.UUID
    organization_name: str
    role: Role


class MeResponse(BaseModel):
    """The caller."""

    kind: PrincipalKind
    id: uuid.UUID
    email: str | None = None
    name: str | None = None
    is_superuser: bool = False
    organization_id: uuid.UUID | None
    role: Role | None
    memberships: list[MembershipOut] = []
    session_id: uuid.UUID
    session_expires_at: Timestamp
