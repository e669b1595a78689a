"""Reads of the audit log."""

from __future__ import annotations

from server.audit.models import AuditEvent
from server.kit.paging import Page, Paged, paginate
from server.kit.scope import ScopedRepository


class AuditRepository(ScopedRepository[AuditEvent]):
    """Audit events of the caller's organisation, newest first."""

    model = AuditEvent
    noun = "audit event"

    async def recent(self, page: Page, action: str | None = None) -> Paged[AuditEvent]:
        """The newest events, optionally of one action."""
        stmt = self.select().order_by(AuditEvent.at.desc(), AuditEvent.id)
        if action:
            stmt = stmt.where(AuditEvent.action == action)
        return await paginate(self.db, stmt, page)
