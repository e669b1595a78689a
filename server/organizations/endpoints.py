"""HTTP routes of organisations and their users."""

from __future__ import annotations

import uuid
from typing import Annotated

from fastapi import APIRouter, Depends, Query, Request, Response

from server.audit.service import record
from server.auth.service import SessionService
from server.deps import (
    DB,
    Admin,
    CurrentPrincipal,
    PasswordsDep,
    SettingsDep,
    Superuser,
    Viewer,
    client_addr,
    require,
)
from server.kit.errors import Conflict, NotFound
from server.kit.scope import Principal
from server.organizations import service
from server.organizations.models import Membership, Role, User
from server.organizations.repository import MembershipRepository, OrganizationRepository
from server.organizations.schemas import (
    OrganizationCreate,
    OrganizationOut,
    UserCreate,
    UserOut,
    UserUpdate,
)

router = APIRouter(tags=["organizations"])
_viewer = require(Role.viewer)


async def _viewer_or_superuser(principal: CurrentPrincipal) -> Principal:
    """A viewer of an organisation, or a superuser logged in without one (sees every organisation)."""
    if principal.kind == "user" and principal.is_superuser:
        return principal
    return await _viewer(principal)


ViewerOrSuperuser = Annotated[Principal, Depends(_viewer_or_superuser)]


def _user_out(m: Membership, u: User) -> UserOut:
    return UserOut(
        id=u.id, email=u.email, role=m.role, is_active=u.is_active, created_at=u.created_at
    )


@router.post("/api/v1/organizations", status_code=201, response_model=OrganizationOut)
async def create_organization(
    body: OrganizationCreate, principal: Superuser, request: Request, db: DB
) -> OrganizationOut:
    """Create an organisation (platform superusers only)."""
    org = await service.create_organization(db, body.name)
    await record(
        db,
        "organization.created",
        organization_id=org.id,
        actor_kind="user",
        actor_id=principal.actor_id,
        target=org.name,
        client_addr=client_addr(request),
    )
    return OrganizationOut.model_validate(org)


@router.get("/api/v1/organizations", response_model=list[OrganizationOut])
async def list_organizations(
    principal: ViewerOrSuperuser,
    db: DB,
    limit: int = Query(100, ge=1, le=1000),
    offset: int = Query(0, ge=0, le=10**9),
) -> list[OrganizationOut]:
    """Organisations visible to the caller: all for a superuser, one's own otherwise."""
    repo = OrganizationRepository(db)
    if principal.is_superuser:
        return [OrganizationOut.model_validate(o) for o in await repo.all(limit, offset)]
    org = await repo.by_id(principal.organization_id)  # type: ignore[arg-type]
    return [OrganizationOut.model_validate(org)] if org and offset == 0 else []


@router.get("/api/v1/organizations/{organization_id}", response_model=OrganizationOut)
async def get_organization(
    organization_id: uuid.UUID, principal: ViewerOrSuperuser, db: DB
) -> OrganizationOut:
    """One organisation: one's own, or any for a superuser."""
    org = await OrganizationRepository(db).by_id(organization_id)
    if org is None or (org.id != principal.organization_id and not principal.is_superuser):
        raise NotFound(f"organisation {organization_id} not found")
    return OrganizationOut.model_validate(org)


@router.get("/api/v1/users", response_model=list[UserOut])
async def list_users(
    principal: Viewer,
    db: DB,
    limit: int = Query(100, ge=1, le=1000),
    offset: int = Query(0, ge=0, le=10**9),
) -> list[UserOut]:
    """Members of the caller's organisation."""
    rows = await MembershipRepository(db, principal).with_users(limit, offset)
    return [_user_out(m, u) for m, u in rows]


@router.post("/api/v1/users", status_code=201, response_model=UserOut)
async def create_user(
    body: UserCreate, principal: Admin, request: Request, db: DB, passwords: PasswordsDep
) -> UserOut:
    """Create a user in the caller's organisation (admins only)."""
    user = await service.create_user(db, passwords, email=body.email, password=body.password)
    m = await service.add_member(db, principal.organization_id, user.id, body.role)  # type: ignore[arg-type]
    await record(
        db,
        "user.created",
        organization_id=principal.organization_id,
        actor_kind="user",
        actor_id=principal.actor_id,
        target=user.email,
        client_addr=client_addr(request),
        role=body.role.value,
    )
    return _user_out(m, user)


async def _member(db: DB, principal: Viewer, user_id: uuid.UUID) -> tuple[Membership, User]:
    found = await MembershipRepository(db, principal).of_user(user_id)
    if found is None:
        raise NotFound(f"user {user_id} not found")
    return found


@router.get("/api/v1/users/{user_id}", response_model=UserOut)
async def get_user(user_id: uuid.UUID, principal: Viewer, db: DB) -> UserOut:
    """One member of the caller's organisation."""
    return _user_out(*await _member(db, principal, user_id))


@router.patch("/api/v1/users/{user_id}", response_model=UserOut)
async def update_user(
    user_id: uuid.UUID,
    body: UserUpdate,
    principal: Admin,
    request: Request,
    db: DB,
    settings: SettingsDep,
) -> UserOut:
    """Change a member's role or disable the account (admins only)."""
    m, u = await _member(db, principal, user_id)
    if u.id == principal.user_id and body.role not in (None, Role.admin):
        raise Conflict("you cannot lower your own role", code="self_demotion")
    if body.role is not None:
        m.role = body.role
    if body.is_active is not None:
        u.is_active = body.is_active
        if not body.is_active:
            await SessionService(db, settings).end_all_for_user(u.id, "disabled")
    await record(
        db,
        "user.updated",
        organization_id=principal.organization_id,
        actor_kind="user",
        actor_id=principal.actor_id,
        target=u.email,
        client_addr=client_addr(request),
        changes=body.model_dump(exclude_none=True, mode="json"),
    )
    await db.flush()
    return _user_out(m, u)


@router.delete("/api/v1/users/{user_id}", status_code=204, response_class=Response)
async def remove_user(
    user_id: uuid.UUID, principal: Admin, request: Request, db: DB, settings: SettingsDep
) -> Response:
    """Remove a member from the caller's organisation and end their sessions there (admins only)."""
    m, u = await _member(db, principal, user_id)
    if u.id == principal.user_id:
        raise Conflict("you cannot remove yourself", code="self_removal")
    await SessionService(db, settings).end_all_for_user(u.id, "removed", principal.organization_id)
    await db.delete(m)
    await record(
        db,
        "user.removed",
        organization_id=principal.organization_id,
        actor_kind="user",
        actor_id=principal.actor_id,
        target=u.email,
        client_addr=client_addr(request),
    )
    return Response(status_code=204)
