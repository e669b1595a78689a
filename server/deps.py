"""FastAPI dependencies: the unit of work, the caller's identity, role requirements."""

from __future__ import annotations

from collections.abc import AsyncIterator, Callable, Coroutine
from typing import Annotated, Any

from fastapi import Depends, FastAPI, Request
from fastapi.security import HTTPAuthorizationCredentials, HTTPBearer
from sqlalchemy.ext.asyncio import AsyncSession
from starlette.requests import HTTPConnection

from server.auth.models import AuthSession
from server.auth.service import SessionService
from server.config import Settings
from server.kit.errors import Forbidden, Unauthorized, Unavailable
from server.kit.openapi import declares
from server.kit.principal import Principal, Role
from server.kit.security import Passwords
from server.kit.uow import UnitOfWork, unit_of_work
from server.organizations.models import User
from server.organizations.repository import MembershipRepository
from server.services import Services


def set_services(app: FastAPI, services: Services) -> None:
    """Hand the lifespan's services to the app's routes."""
    app.state.services = services


def services_of(app: FastAPI) -> Services:
    """The services of a running app (built by its lifespan)."""
    services = app.state.services
    if not isinstance(services, Services):  # never expected: the lifespan sets it before serving
        raise RuntimeError("the app's lifespan has not built its services")
    return services


def get_services(conn: HTTPConnection) -> Services:
    """The server's services, for an HTTP request or a WebSocket."""
    return services_of(conn.app)


ServicesDep = Annotated[Services, Depends(get_services)]


@declares(Unavailable)
async def get_uow(request: Request) -> AsyncIterator[UnitOfWork]:
    """One unit of work per request: committed once when the endpoint succeeds (then its
    after-commit hooks run), rolled back otherwise. Endpoints and services never commit."""
    services = get_services(request)
    async with unit_of_work(
        services.sessionmaker,
        client_addr=client_addr(request),
        session_end_listeners=services.session_end_listeners,
    ) as uow:
        yield uow


def get_db(uow: Annotated[UnitOfWork, Depends(get_uow, scope="function")]) -> AsyncSession:
    """The session of the request's unit of work (prefer a service taking the `UoW`)."""
    return uow.db


def get_settings(request: Request) -> Settings:
    """The server's settings."""
    return get_services(request).settings


def get_passwords(request: Request) -> Passwords:
    """The configured password hasher."""
    return get_services(request).passwords


# scope="function": commit before the response is sent, so a client never reads before the write lands
UoW = Annotated[UnitOfWork, Depends(get_uow, scope="function")]
DB = Annotated[AsyncSession, Depends(get_db, scope="function")]
SettingsDep = Annotated[Settings, Depends(get_settings)]
PasswordsDep = Annotated[Passwords, Depends(get_passwords)]


# the one security scheme of the document (`bearerAuth`): every operation that reads it declares it
bearer = HTTPBearer(
    scheme_name="bearerAuth",
    bearerFormat="opaque",
    description="The `access_token` of POST /api/v1/auth/login (users) or /api/v1/assets/login "
    "(assets), sent as `Authorization: Bearer <token>`.",
    auto_error=False,  # a missing token is our 401 with the error envelope, not FastAPI's 403
)
Credentials = Annotated[HTTPAuthorizationCredentials | None, Depends(bearer)]


def bearer_token(credentials: HTTPAuthorizationCredentials | None) -> str | None:
    """The bearer token of the request's `Authorization` header, if any."""
    if credentials is None or not credentials.credentials.strip():
        return None
    return credentials.credentials.strip()


async def principal_of(
    uow: UnitOfWork, settings: Settings, token: str | None
) -> tuple[Principal, AuthSession]:
    """Resolve a token to the caller; raises Unauthorized."""
    if not token:
        raise Unauthorized()
    db = uow.db
    session = await SessionService(uow, settings).authenticate(token)
    if session.principal_kind == "asset":
        return Principal(
            kind="asset",
            session_id=session.id,
            organization_id=session.organization_id,
            asset_id=session.asset_id,
        ), session
    user = await db.get(User, session.user_id)
    if user is None or not user.is_active:
        raise Unauthorized("account disabled", code="account_disabled")
    role: Role | None = None
    if session.organization_id is not None:
        probe = Principal(
            kind="user", session_id=session.id, organization_id=session.organization_id
        )
        found = await MembershipRepository(db, probe).of_user(user.id)
        if found is not None and not found[0].is_active:
            raise Unauthorized("account disabled in this organisation", code="account_disabled")
        if found is not None:
            role = found[0].role
        elif user.is_superuser:
            role = Role.admin
    return Principal(
        kind="user",
        session_id=session.id,
        organization_id=session.organization_id if role else None,
        role=role,
        user_id=user.id,
        is_superuser=user.is_superuser,
        label=user.email,
    ), session


@declares(Unauthorized)
async def current_session(uow: UoW, settings: SettingsDep, credentials: Credentials) -> AuthSession:
    """The caller's live session."""
    return (await principal_of(uow, settings, bearer_token(credentials)))[1]


@declares(Unauthorized)
async def current_principal(
    request: Request, uow: UoW, settings: SettingsDep, credentials: Credentials
) -> Principal:
    """The caller (user or asset), from its bearer token."""
    principal, _ = await principal_of(uow, settings, bearer_token(credentials))
    request.state.principal = principal
    return principal


CurrentPrincipal = Annotated[Principal, Depends(current_principal)]
CurrentSession = Annotated[AuthSession, Depends(current_session)]


def require(role: Role) -> Callable[..., Coroutine[Any, Any, Principal]]:
    """A dependency admitting users whose role in their organisation is at least `role`."""

    @declares(Forbidden)
    async def dependency(principal: CurrentPrincipal) -> Principal:
        if principal.kind != "user":
            raise Forbidden("asset sessions cannot call this endpoint")
        if principal.role is None or not principal.role.allows(role):
            have = principal.role.value if principal.role else "no role"
            raise Forbidden(f"this needs the {role.value} role; you have {have}")
        return principal

    dependency.min_role = role  # type: ignore[attr-defined]  # read by the authorization test
    return dependency


@declares(Forbidden)
async def require_superuser(principal: CurrentPrincipal) -> Principal:
    """A dependency admitting platform superusers only."""
    if principal.kind != "user" or not principal.is_superuser:
        raise Forbidden("this needs a platform superuser")
    return principal


Viewer = Annotated[Principal, Depends(require(Role.viewer))]
Operator = Annotated[Principal, Depends(require(Role.operator))]
Admin = Annotated[Principal, Depends(require(Role.admin))]
Superuser = Annotated[Principal, Depends(require_superuser)]


def client_addr(request: Request) -> str | None:
    """The client's address as seen by this server."""
    return request.client.host if request.client else None
