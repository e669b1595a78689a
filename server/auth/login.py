"""Logging in (limits on failed attempts, credentials, disabled accounts, the one-session rule)
and telling callers who they are."""

from __future__ import annotations

import asyncio
import uuid

from server.assets.models import Asset
from server.assets.repository import AssetRepository
from server.auth.limiter import LoginLimiter
from server.auth.models import AuthSession
from server.auth.schemas import MembershipOut, MeResponse, PrincipalKind
from server.auth.service import Account, IssuedToken, SessionService
from server.config import Settings
from server.kit.errors import Unauthorized, Unprocessable
from server.kit.security import Passwords, same_hash, token_hash
from server.kit.service import Service
from server.kit.time import utcnow
from server.kit.uow import UnitOfWork
from server.organizations.models import Membership, Organization, User
from server.organizations.repository import UserRepository

DISABLED = "this account is disabled; ask an administrator of the organisation"
WRONG_PASSWORD = "wrong e-mail or password"


def _hash(user: User | None) -> str | None:
    return user.password_hash if user else None


def _organisation(
    user: User, memberships: list[tuple[Membership, Organization]], wanted: uuid.UUID | None
) -> uuid.UUID | None:
    """The organisation a login is for: the one asked for, else the first where the user is
    active; Unauthorized(account_disabled) when the user is disabled there (or everywhere)."""
    if wanted is not None:
        found = [m for m, o in memberships if o.id == wanted]
        if not found and not user.is_superuser:
            raise Unprocessable("you are not a member of that organisation", code="not_a_member")
        if found and not found[0].is_active:
            raise Unauthorized(DISABLED, code="account_disabled")
        return wanted
    active = [o.id for m, o in memberships if m.is_active]
    if memberships and not active and not user.is_superuser:
        raise Unauthorized(DISABLED, code="account_disabled")
    return active[0] if active else None


class LoginService:
    """Logs users and assets in; like every auth service it runs before there is a caller."""

    def __init__(
        self, uow: UnitOfWork, settings: Settings, passwords: Passwords, limiter: LoginLimiter
    ) -> None:
        self.uow = uow
        self.settings = settings
        self.passwords = passwords
        self.limiter = limiter

    async def user(
        self, email: str, password: str, *, force: bool, organization_id: uuid.UUID | None
    ) -> IssuedToken:
        """A user's login: at most the limit of concurrent wrong passwords is ever checked, and
        a wrong one repeated from the same address is not counted again."""
        addr = self.uow.client_addr
        # a session of its own, returned before the next is taken: the request's would be held
        # while the limiter's waits for the pool (under a burst of logins, none would come)
        async with self.limiter.sessionmaker() as db:
            known = await UserRepository(db).by_email(email)
        if self.limiter.repeated("user", email, addr, password, _hash(known)):
            raise Unauthorized(WRONG_PASSWORD, code="invalid_credentials")
        attempt = await self.limiter.admit(email, addr, utcnow())
        users = UserRepository(self.uow.db)
        user = await users.by_email(email, lock=True)
        # argon2 is deliberately slow: keep it off the event loop
        ok = await asyncio.to_thread(self.passwords.verify, _hash(user), password)
        # held for this transaction, the password still the one checked (see `asset`)
        ok = ok and user is not None and await users.claim_for_login(user.id, user.password_hash)
        if not ok or user is None:
            self.limiter.wrong("user", email, addr, password, _hash(user))
            raise Unauthorized(WRONG_PASSWORD, code="invalid_credentials")
        # the password was right: this is no failed attempt, whatever follows
        await self.limiter.succeeded(self.uow.db, email, addr, attempt)
        self.limiter.outcome("user", "ok")
        if not user.is_active:
            raise Unauthorized(DISABLED, code="account_disabled")
        org_id = _organisation(user, await users.memberships(user.id), organization_id)
        return await SessionService(self.uow, self.settings).open(
            Account("user", user.id, org_id, user.email), force=force
        )

    async def asset(self, name: str, secret: str, *, force: bool) -> IssuedToken:
        """An asset's login. The right secret always gets in (256 random bits: nothing to guess);
        wrong ones are counted by source and by asset name, and answered 429 past the limits."""
        # a session of its own, returned before the limiter takes one (as for users): a burst of
        # wrong secrets would otherwise hold the pool, each request waiting for a second one
        async with self.limiter.sessionmaker() as db:
            found = await AssetRepository.by_name_for_login(db, name)
        if found is None or not same_hash(found.secret_hash, token_hash(secret)):
            await self.limiter.admit(f"asset:{name}", self.uow.client_addr, utcnow(), door="asset")
            self.limiter.outcome("asset", "wrong")
            raise Unauthorized("wrong asset name or secret", code="invalid_credentials")
        # the right secret: the asset held for this login's transaction, on condition that its
        # secret is still that one. Nothing of the login is read in the transaction before this
        # write: concurrent logins and a rotation of the asset take turns from here on every
        # database, so the session rule (`SessionService.open`) reads the asset's current
        # sessions, and a login that a rotation overtook is refused instead of opening a session
        # on the old secret (not counted: that secret was right a moment ago, it is no guess)
        if not await AssetRepository.claim_for_login(self.uow.db, found.id, found.secret_hash):
            self.limiter.outcome("asset", "wrong")
            raise Unauthorized("wrong asset name or secret", code="invalid_credentials")
        self.limiter.outcome("asset", "ok")
        return await SessionService(self.uow, self.settings).open(
            Account("asset", found.id, found.organization_id, found.name),
            force=force,
            via="asset.login",
        )


class IdentityService(Service):
    """Who the caller is."""

    async def me(self, session: AuthSession) -> MeResponse:
        """The caller, its organisation and role, and (a user's) memberships."""
        p = self.principal
        if p.kind == "asset":
            asset = await self.db.get(Asset, p.asset_id)
            return MeResponse(
                kind=PrincipalKind.asset,
                id=p.asset_id,  # type: ignore[arg-type]
                name=asset.name if asset else None,
                organization_id=p.organization_id,
                role=None,
                session_id=session.id,
                session_expires_at=session.expires_at,
            )
        memberships = await UserRepository(self.db).memberships(p.user_id)  # type: ignore[arg-type]
        return MeResponse(
            kind=PrincipalKind.user,
            id=p.user_id,  # type: ignore[arg-type]
            email=p.label,
            is_superuser=p.is_superuser,
            organization_id=p.organization_id,
            role=p.role,
            memberships=[
                MembershipOut(organization_id=o.id, organization_name=o.name, role=m.role)
                for m, o in memberships
            ],
            session_id=session.id,
            session_expires_at=session.expires_at,
        )
