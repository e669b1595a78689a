"""Reads of the audit log."""

from __future__ import annotations

from server.audit.models import AuditEvent
from server.kit.scope import ScopedRepository


class AuditRepository(ScopedRepository[AuditEvent]):
    """Audit events of the caller's organisation, newest first."""

    model = AuditEvent
    noun = "audit event"

    async def recent(self, limit: int, action: str | None = None) -> list[AuditEvent]:
        """The newest events, optionally of one action."""
        stmt = self.select().order_by(AuditEvent.at.desc()).limit(limit)
        if action:
            stmt = stmt.where(AuditEvent.action == action)
        return list((await self.db.execute(stmt)).scalars())
