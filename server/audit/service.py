"""The audit log: the one helper every service records through (in its unit of work), and reads."""

from __future__ import annotations

import uuid
from typing import Any

from server.audit.models import AuditEvent
from server.audit.repository import AuditRepository
from server.kit.paging import Page, Paged
from server.kit.principal import Principal
from server.kit.service import Service
from server.kit.uow import UnitOfWork


async def record(
    uow: UnitOfWork,
    actor: Principal,
    action: str,
    *,
    target: str | None = None,
    organization_id: uuid.UUID | None = None,
    **details: Any,
) -> None:
    """Add one audit event (who, what, on what, from where) to the unit of work.

    The organisation is the actor's unless given (a superuser creating one names the new one)."""
    uow.db.add(
        AuditEvent(
            action=action,
            organization_id=organization_id or actor.organization_id,
            actor_kind=actor.kind,
            actor_id=actor.actor_id,
            target=target,
            client_addr=uow.client_addr,
            details=details,
        )
    )
    await uow.db.flush()


class AuditService(Service):
    """Reading the audit log of the caller's organisation."""

    async def recent(self, page: Page, action: str | None) -> Paged[AuditEvent]:
        """The newest events, optionally of one action."""
        return await AuditRepository(self.db, self.principal).recent(page, action)
