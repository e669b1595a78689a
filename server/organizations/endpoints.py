"""HTTP routes of organisations and their users."""

from __future__ import annotations

import uuid
from typing import Annotated

from fastapi import APIRouter, Depends, Response

from server.deps import (
    Admin,
    CurrentPrincipal,
    PasswordsDep,
    SettingsDep,
    Superuser,
    UoW,
    Viewer,
    require,
)
from server.kit.errors import Conflict, Forbidden
from server.kit.etag import CREATED_TAGGED, TAGGED, IfMatchDep, tag
from server.kit.openapi import declares, errors
from server.kit.paging import PAGED, Paging
from server.kit.principal import Principal, Role
from server.organizations.models import Membership, User
from server.organizations.schemas import (
    OrganizationCreate,
    OrganizationOut,
    PasswordReset,
    UserCreate,
    UserOut,
    UserUpdate,
)
from server.organizations.service import OrganizationService

router = APIRouter(tags=["organizations"])
_viewer = require(Role.viewer)


@declares(Forbidden)
async def _viewer_or_superuser(principal: CurrentPrincipal) -> Principal:
    """A viewer of an organisation, or a superuser logged in without one (sees every organisation)."""
    if principal.kind == "user" and principal.is_superuser:
        return principal
    return await _viewer(principal)


ViewerOrSuperuser = Annotated[Principal, Depends(_viewer_or_superuser)]


def _user_out(m: Membership, u: User) -> UserOut:
    return UserOut(
        id=u.id,
        email=u.email,
        role=m.role,
        is_active=m.is_active and u.is_active,
        created_at=u.created_at,
    )


def _service(uow: UoW, principal: Viewer, settings: SettingsDep) -> OrganizationService:
    return OrganizationService(uow, principal, settings)


def _org_reader_service(
    uow: UoW, principal: ViewerOrSuperuser, settings: SettingsDep
) -> OrganizationService:
    return OrganizationService(uow, principal, settings)


def _admin_service(uow: UoW, principal: Admin, settings: SettingsDep) -> OrganizationService:
    return OrganizationService(uow, principal, settings)


def _super_service(uow: UoW, principal: Superuser, settings: SettingsDep) -> OrganizationService:
    return OrganizationService(uow, principal, settings)


Orgs = Annotated[OrganizationService, Depends(_service)]
OrgsReader = Annotated[OrganizationService, Depends(_org_reader_service)]
OrgsAdmin = Annotated[OrganizationService, Depends(_admin_service)]
OrgsSuper = Annotated[OrganizationService, Depends(_super_service)]


@router.post(
    "/api/v1/organizations",
    status_code=201,
    response_model=OrganizationOut,
    responses=errors(Conflict),
)
async def create_organization(body: OrganizationCreate, orgs: OrgsSuper) -> OrganizationOut:
    """Create an organisation (platform superusers only)."""
    return OrganizationOut.model_validate(await orgs.create_organization(body.name))


@router.get("/api/v1/organizations", response_model=list[OrganizationOut], responses=PAGED)
async def list_organizations(orgs: OrgsReader, pages: Paging) -> list[OrganizationOut]:
    """Organisations visible to the caller: all for a superuser, one's own otherwise."""
    found = await orgs.organizations(pages.page)
    pages.respond(found.total)
    return [OrganizationOut.model_validate(o) for o in found.items]


@router.get("/api/v1/organizations/{organization_id}", response_model=OrganizationOut)
async def get_organization(organization_id: uuid.UUID, orgs: OrgsReader) -> OrganizationOut:
    """One organisation: one's own, or any for a superuser."""
    return OrganizationOut.model_validate(await orgs.organization(organization_id))


@router.get("/api/v1/users", response_model=list[UserOut], responses=PAGED)
async def list_users(orgs: Orgs, pages: Paging) -> list[UserOut]:
    """Members of the caller's organisation, oldest first."""
    found = await orgs.users(pages.page)
    pages.respond(found.total)
    return [_user_out(m, u) for m, u in found.items]


@router.post(
    "/api/v1/users",
    status_code=201,
    response_model=UserOut,
    responses={**CREATED_TAGGED, **errors(Conflict)},
)
async def create_user(
    body: UserCreate, orgs: OrgsAdmin, passwords: PasswordsDep, response: Response
) -> UserOut:
    """Create a user in the caller's organisation (admins only)."""
    m, user = await orgs.create_user(
        passwords, email=body.email, password=body.password, role=body.role
    )
    tag(response, m.version)
    return _user_out(m, user)


@router.get("/api/v1/users/{user_id}", response_model=UserOut, responses=TAGGED)
async def get_user(user_id: uuid.UUID, orgs: Orgs, response: Response) -> UserOut:
    """One member of the caller's organisation, the ETag of the membership in the header."""
    m, user = await orgs.user(user_id)
    tag(response, m.version)
    return _user_out(m, user)


@router.patch(
    "/api/v1/users/{user_id}",
    response_model=UserOut,
    responses={**TAGGED, **errors(Conflict)},
)
async def update_user(
    user_id: uuid.UUID,
    body: UserUpdate,
    orgs: OrgsAdmin,
    expect: IfMatchDep,
    response: Response,
) -> UserOut:
    """Change a member's role or disable them in this organisation (admins only); with
    `If-Match`, only the version it names (else 412)."""
    m, user = await orgs.update_user(
        user_id, role=body.role, is_active=body.is_active, expect=expect
    )
    tag(response, m.version)
    return _user_out(m, user)


@router.post(
    "/api/v1/users/{user_id}/password",
    status_code=204,
    response_class=Response,
    responses=errors(Conflict, Forbidden),
)
async def reset_user_password(
    user_id: uuid.UUID, body: PasswordReset, orgs: OrgsAdmin, passwords: PasswordsDep
) -> Response:
    """Give a member a new password (admins only); every session of theirs ends. Not for
    oneself (`POST /api/v1/auth/password`), nor, but by a superuser, for a superuser or a member
    of other organisations too."""
    await orgs.reset_password(passwords, user_id, body.new_password)
    return Response(status_code=204)


@router.delete(
    "/api/v1/users/{user_id}",
    status_code=204,
    response_class=Response,
    responses=errors(Conflict),
)
async def remove_user(user_id: uuid.UUID, orgs: OrgsAdmin, expect: IfMatchDep) -> Response:
    """Remove a member from the caller's organisation and end their sessions there (admins only);
    with `If-Match`, only the version it names (else 412)."""
    await orgs.remove_user(user_id, expect)
    return Response(status_code=204)
