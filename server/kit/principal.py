"""Who is calling: the roles of an organisation and the caller's identity.

In the kit, not in a domain, so that the kit (scoping, the unit of work) and every domain can
name them without the kit importing a domain.
"""

from __future__ import annotations

import enum
import uuid
from dataclasses import dataclass


class Role(enum.StrEnum):
    """Roles inside an organisation, weakest first."""

    viewer = "viewer"
    operator = "operator"
    admin = "admin"

    @property
    def rank(self) -> int:
        """Position in the order viewer < operator < admin."""
        return list(Role).index(self)

    def allows(self, needed: Role) -> bool:
        """True when this role is at least `needed`."""
        return self.rank >= needed.rank


@dataclass(frozen=True)
class Principal:
    """Who is calling: a user (with a role in one organisation) or an asset."""

    kind: str  # "user" | "asset"
    session_id: uuid.UUID
    organization_id: uuid.UUID | None
    role: Role | None = None
    user_id: uuid.UUID | None = None
    asset_id: uuid.UUID | None = None
    is_superuser: bool = False
    label: str = ""  # e-mail or asset name, for logs and audit

    @property
    def actor_id(self) -> str:
        """The id written into the audit log."""
        return str(self.user_id or self.asset_id)
