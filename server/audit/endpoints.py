"""HTTP route of the audit log."""

from __future__ import annotations

from fastapi import APIRouter, Query

from server.audit.schemas import AuditEventOut
from server.audit.service import AuditService
from server.deps import Admin, UoW

router = APIRouter(tags=["audit"])


@router.get("/api/v1/audit", response_model=list[AuditEventOut])
async def list_audit(
    principal: Admin,
    uow: UoW,
    limit: int = Query(100, ge=1, le=1000),
    action: str | None = Query(None, max_length=64),
) -> list[AuditEventOut]:
    """The newest audit events of the caller's organisation (admins only)."""
    rows = await AuditService(uow, principal).recent(limit, action)
    return [AuditEventOut.model_validate(r) for r in rows]
