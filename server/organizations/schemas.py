"""API shapes of organisations and users."""

from __future__ import annotations

import uuid

from pydantic import BaseModel, ConfigDict

from server.kit.principal import Role
from server.kit.types import Email, Name, Password, Timestamp


class OrganizationCreate(BaseModel):
    """A new organisation."""

    model_config = ConfigDict(extra="forbid")
    name: Name


class OrganizationOut(BaseModel):
    """An organisation."""

    model_config = ConfigDict(from_attributes=True)
    id: uuid.UUID
    name: str
    created_at: Timestamp


class UserCreate(BaseModel):
    """A new user in the caller's organisation."""

    model_config = ConfigDict(extra="forbid")
    email: Email
    password: Password
    role: Role


class UserUpdate(BaseModel):
    """Changes to a member: role, or disabling the account."""

    model_config = ConfigDict(extra="forbid")
    role: Role | None = None
    is_active: bool | None = None


class PasswordReset(BaseModel):
    """A member's new password, set by an administrator (12 characters or more)."""

    model_config = ConfigDict(extra="forbid")
    new_password: Password


class UserOut(BaseModel):
    """A member of the caller's organisation."""

    id: uuid.UUID
    email: str
    role: Role
    is_active: bool
    created_at: Timestamp
