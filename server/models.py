"""Imports every table so that metadata (and Alembic autogenerate) sees them all."""

from server.assets.models import Asset, AssetKind
from server.audit.models import AuditEvent
from server.auth.models import AuthSession, LoginFailure
from server.kit.db import Base
from server.organizations.models import Membership, Organization, Role, User

__all__ = ["Asset", "AssetKind", "AuditEvent", "AuthSession", "Base", "LoginFailure", "Membership",
           "Organization", "Role", "User"]
