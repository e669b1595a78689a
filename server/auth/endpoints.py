"""HTTP routes of login, logout, renewal, identity and the caller's password."""

from __future__ import annotations

from typing import Annotated

from fastapi import APIRouter, Depends, Response

from server.auth.login import IdentityService, LoginService
from server.auth.password import PasswordService, WrongPassword
from server.auth.schemas import (
    AssetLoginRequest,
    LoginRequest,
    MeResponse,
    PasswordChange,
    TokenResponse,
)
from server.auth.service import IssuedToken, SessionService
from server.deps import CurrentPrincipal, CurrentSession, ServicesDep, SettingsDep, UoW
from server.kit.errors import (
    Conflict,
    Forbidden,
    RateLimited,
    Unauthorized,
    Unprocessable,
    answer,
)
from server.kit.openapi import declares, errors

router = APIRouter(tags=["auth"])


def _token(issued: IssuedToken) -> TokenResponse:
    return TokenResponse(
        access_token=issued.access_token,
        expires_at=issued.session.expires_at,
        session_id=issued.session.id,
    )


@declares(Unauthorized, Conflict, RateLimited)  # wrong credentials, a live session, throttled
def _logins(uow: UoW, services: ServicesDep) -> LoginService:
    return LoginService(uow, services.settings, services.passwords, services.limiter)


Logins = Annotated[LoginService, Depends(_logins)]


@router.post(
    "/api/v1/auth/login",
    response_model=TokenResponse,
    responses={
        409: {"description": "a live session exists (send force=true)"},
        429: {"description": "too many failed logins (see Retry-After)"},
    },
)
async def login(body: LoginRequest, logins: Logins) -> TokenResponse:
    """Log a user in. One live session per account: 409 unless `force` ends the other one."""
    issued = await logins.user(
        body.email, body.password, force=body.force, organization_id=body.organization_id
    )
    return _token(issued)


@router.post(
    "/api/v1/assets/login",
    response_model=TokenResponse,
    tags=["assets"],
    responses={409: {"description": "the asset has a live session"}},
)
async def asset_login(body: AssetLoginRequest, logins: Logins) -> TokenResponse:
    """Log an asset in with its name and secret (from its configuration file)."""
    return _token(await logins.asset(body.name, body.secret, force=body.force))


@router.post("/api/v1/auth/renew", response_model=TokenResponse, operation_id="renewSession")
async def renew(session: CurrentSession, uow: UoW, settings: SettingsDep) -> TokenResponse:
    """Give the caller's session a new token and expiry; the old token and its sockets stop."""
    token = await SessionService(uow, settings).renew(session)
    return TokenResponse(access_token=token, expires_at=session.expires_at, session_id=session.id)


@router.post("/api/v1/auth/logout", status_code=204, response_class=Response)
async def logout(session: CurrentSession, uow: UoW, settings: SettingsDep) -> Response:
    """End the caller's session (its sockets close once this commits)."""
    await SessionService(uow, settings).end(session, "logout")
    return Response(status_code=204)


@router.post(
    "/api/v1/auth/password",
    status_code=204,
    response_class=Response,
    responses=errors(Forbidden, Unprocessable, RateLimited),
)
async def change_password(
    body: PasswordChange,
    principal: CurrentPrincipal,
    session: CurrentSession,
    uow: UoW,
    services: ServicesDep,
) -> Response:
    """Change the caller's password (a user's); the caller's session goes on, every other
    session of the user ends. A wrong `current_password` counts as a failed login."""
    passwords = PasswordService(uow, services.settings, services.passwords, services.limiter)
    try:
        await passwords.change(principal, session, body.current_password, body.new_password)
    except WrongPassword as wrong:  # answered, not raised: its failed attempt is committed
        return answer(wrong)
    return Response(status_code=204)


@router.get("/api/v1/auth/me", response_model=MeResponse, operation_id="getMe")
async def me(principal: CurrentPrincipal, session: CurrentSession, uow: UoW) -> MeResponse:
    """Who the caller is, in which organisation, with which role."""
    return await IdentityService(uow, principal).me(session)
