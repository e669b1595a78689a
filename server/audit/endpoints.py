"""HTTP route of the audit log."""

from __future__ import annotations

import uuid
from datetime import datetime
from typing import Any

from fastapi import APIRouter, Query
from pydantic import BaseModel, ConfigDict

from server.audit.repository import AuditRepository
from server.deps import DB, Admin

router = APIRouter(tags=["audit"])


class AuditEventOut(BaseModel):
    """One audit event."""

    model_config = ConfigDict(from_attributes=True)
    id: uuid.UUID
    at: datetime
    actor_kind: str
    actor_id: str | None
    action: str
    target: str | None
    client_addr: str | None
    details: dict[str, Any]


@router.get("/api/v1/audit", response_model=list[AuditEventOut])
async def list_audit(
    principal: Admin,
    db: DB,
    limit: int = Query(100, ge=1, le=1000),
    action: str | None = Query(None, max_length=64),
) -> list[AuditEventOut]:
    """The newest audit events of the caller's organisation (admins only)."""
    rows = await AuditRepository(db, principal).recent(limit, action)
    return [AuditEventOut.model_validate(r) for r in rows]
