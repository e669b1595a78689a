"""HTTP route of the audit log."""

from __future__ import annotations

from fastapi import APIRouter, Query

from server.audit.schemas import AuditEventOut
from server.audit.service import AuditService
from server.deps import Admin, UoW
from server.kit.paging import PAGED, Paging

router = APIRouter(tags=["audit"])


@router.get("/api/v1/audit", response_model=list[AuditEventOut], responses=PAGED)
async def list_audit(
    principal: Admin,
    uow: UoW,
    pages: Paging,
    action: str | None = Query(None, max_length=64),
) -> list[AuditEventOut]:
    """The newest audit events of the caller's organisation (admins only)."""
    found = await AuditService(uow, principal).recent(pages.page, action)
    pages.respond(found.total)
    return [AuditEventOut.model_validate(r) for r in found.items]
