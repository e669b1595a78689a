"""Writing audit events (in the caller's unit of work)."""

from __future__ import annotations

import uuid
from typing import Any

from sqlalchemy.ext.asyncio import AsyncSession

from server.audit.models import AuditEvent


async def record(
    db: AsyncSession,
    action: str,
    *,
    organization_id: uuid.UUID | None,
    actor_kind: str,
    actor_id: str | None,
    target: str | None = None,
    client_addr: str | None = None,
    **details: Any,
) -> None:
    """Add one audit event to the current unit of work."""
    db.add(
        AuditEvent(
            action=action,
            organization_id=organization_id,
            actor_kind=actor_kind,
            actor_id=actor_id,
            target=target,
            client_addr=client_addr,
            details=details,
        )
    )
    await db.flush()
