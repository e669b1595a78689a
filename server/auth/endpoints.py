"""HTTP routes of login, logout, renewal and identity."""

from __future__ import annotations

import asyncio

from fastapi import APIRouter, Request, Response
from sqlalchemy import select

from server.assets.models import Asset
from server.auth.schemas import (
    AssetLoginRequest,
    LoginRequest,
    MembershipOut,
    MeResponse,
    TokenResponse,
)
from server.auth.service import Account, IssuedToken, RateLimiter, SessionService
from server.deps import (
    DB,
    CurrentPrincipal,
    PasswordsDep,
    SettingsDep,
    client_addr,
    current_session,
    get_services,
)
from server.kit.errors import Unauthorized, Unprocessable
from server.kit.security import same_hash, token_hash
from server.kit.time import utcnow
from server.organizations.repository import UserRepository

router = APIRouter(tags=["auth"])


def _token(issued: IssuedToken) -> TokenResponse:
    return TokenResponse(
        access_token=issued.access_token,
        expires_at=issued.session.expires_at,
        session_id=issued.session.id,
    )


async def _notify_ended(request: Request, issued: IssuedToken) -> None:
    for listener in get_services(request).session_end_listeners:
        await listener(list(issued.ended_sessions))


@router.post(
    "/api/v1/auth/login",
    response_model=TokenResponse,
    responses={
        409: {"description": "a live session exists (send force=true)"},
        429: {"description": "too many failed logins"},
    },
)
async def login(
    body: LoginRequest, request: Request, db: DB, settings: SettingsDep, passwords: PasswordsDep
) -> TokenResponse:
    """Log a user in. One live session per account: 409 unless `force` ends the other one."""
    addr, now = client_addr(request), utcnow()
    limiter = RateLimiter(db, settings)
    await limiter.check(body.email, addr, now)
    users = UserRepository(db)
    user = await users.by_email(body.email, lock=True)
    # argon2 is deliberately slow: keep it off the event loop
    ok = await asyncio.to_thread(
        passwords.verify, user.password_hash if user else None, body.password
    )
    if not ok or user is None or not user.is_active:
        await limiter.failed(body.email, addr, now)
        await db.commit()
        raise Unauthorized("wrong e-mail or password", code="invalid_credentials")
    await limiter.succeeded(body.email)
    memberships = await users.memberships(user.id)
    org_id = None
    if body.organization_id is not None:
        if not any(o.id == body.organization_id for _, o in memberships) and not user.is_superuser:
            raise Unprocessable("you are not a member of that organisation", code="not_a_member")
        org_id = body.organization_id
    elif memberships:
        org_id = memberships[0][1].id
    issued = await SessionService(db, settings).open(
        Account("user", user.id, org_id, user.email), force=body.force, client_addr=addr
    )
    await db.commit()
    await _notify_ended(request, issued)
    return _token(issued)


@router.post(
    "/api/v1/assets/login",
    response_model=TokenResponse,
    tags=["assets"],
    responses={409: {"description": "the asset has a live session"}},
)
async def asset_login(
    body: AssetLoginRequest, request: Request, db: DB, settings: SettingsDep
) -> TokenResponse:
    """Log an asset in with its name and secret (from its configuration file)."""
    addr, now = client_addr(request), utcnow()
    limiter = RateLimiter(db, settings)
    await limiter.check(f"asset:{body.name}", addr, now)
    stmt = (
        select(Asset).where(Asset.name == body.name).with_for_update()
    )  # unscoped: identity lookup
    asset = (await db.execute(stmt)).scalar_one_or_none()
    if asset is None or not same_hash(asset.secret_hash, token_hash(body.secret)):
        await limiter.failed(f"asset:{body.name}", addr, now)
        await db.commit()
        raise Unauthorized("wrong asset name or secret", code="invalid_credentials")
    await limiter.succeeded(f"asset:{body.name}")
    issued = await SessionService(db, settings).open(
        Account("asset", asset.id, asset.organization_id, asset.name),
        force=body.force,
        client_addr=addr,
        via="asset.login",
    )
    await db.commit()
    await _notify_ended(request, issued)
    return _token(issued)


@router.post("/api/v1/auth/renew", response_model=TokenResponse)
async def renew(request: Request, db: DB, settings: SettingsDep) -> TokenResponse:
    """Give the caller's session a new token and expiry; the old token stops working."""
    session = await current_session(request, db, settings)
    token = await SessionService(db, settings).renew(session)
    return TokenResponse(access_token=token, expires_at=session.expires_at, session_id=session.id)


@router.post("/api/v1/auth/logout", status_code=204, response_class=Response)
async def logout(request: Request, db: DB, settings: SettingsDep) -> Response:
    """End the caller's session."""
    session = await current_session(request, db, settings)
    await SessionService(db, settings).end(session, "logout")
    await db.commit()
    for listener in get_services(request).session_end_listeners:
        await listener([session.id])
    return Response(status_code=204)


@router.get("/api/v1/auth/me", response_model=MeResponse)
async def me(
    principal: CurrentPrincipal, request: Request, db: DB, settings: SettingsDep
) -> MeResponse:
    """Who the caller is, in which organisation, with which role."""
    session = await current_session(request, db, settings)
    if principal.kind == "asset":
        asset = await db.get(Asset, principal.asset_id)
        return MeResponse(
            kind="asset",
            id=principal.asset_id,  # type: ignore[arg-type]
            name=asset.name if asset else None,
            organization_id=principal.organization_id,
            role=None,
            session_id=session.id,
            session_expires_at=session.expires_at,
        )
    memberships = await UserRepository(db).memberships(principal.user_id)  # type: ignore[arg-type]
    return MeResponse(
        kind="user",
        id=principal.user_id,  # type: ignore[arg-type]
        email=principal.label,
        is_superuser=principal.is_superuser,
        organization_id=principal.organization_id,
        role=principal.role.value if principal.role else None,
        memberships=[
            MembershipOut(organization_id=o.id, organization_name=o.name, role=m.role.value)
            for m, o in memberships
        ],
        session_id=session.id,
        session_expires_at=session.expires_at,
    )
