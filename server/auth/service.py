"""Decisions about logins and sessions: one live session per account, rate limits, tokens."""

from __future__ import annotations

import uuid
from dataclasses import dataclass
from datetime import datetime, timedelta

from sqlalchemy.ext.asyncio import AsyncSession

from server.audit.service import record
from server.auth.models import AuthSession
from server.auth.repository import LoginFailureRepository, SessionRepository
from server.config import Settings
from server.kit.errors import Conflict, RateLimited, Unauthorized
from server.kit.security import new_token, token_hash
from server.kit.time import utcnow


@dataclass(frozen=True)
class Account:
    """The account a login is for: a user (with the organisation chosen) or an asset."""

    kind: str  # "user" | "asset"
    id: uuid.UUID
    organization_id: uuid.UUID | None
    label: str


@dataclass(frozen=True)
class IssuedToken:
    """A freshly issued bearer token and its session."""

    access_token: str
    session: AuthSession
    ended_sessions: tuple[uuid.UUID, ...]


class RateLimiter:
    """Failed logins per account and per client address, over a sliding window."""

    def __init__(self, db: AsyncSession, settings: Settings) -> None:
        self.repo = LoginFailureRepository(db)
        self.settings = settings

    def _keys(self, account_key: str, addr: str | None) -> list[tuple[str, int]]:
        keys = [(f"account:{account_key}", self.settings.login_max_failures_account)]
        if addr:
            keys.append((f"addr:{addr}", self.settings.login_max_failures_address))
        return keys

    async def check(self, account_key: str, addr: str | None, now: datetime) -> None:
        """Raise RateLimited when the account or the address has too many recent failures."""
        window = timedelta(seconds=self.settings.login_window_s)
        for key, limit in self._keys(account_key, addr):
            count, oldest = await self.repo.window(key, now - window)
            if count >= limit and oldest is not None:
                retry = (oldest + window - now).total_seconds()
                what = "this account" if key.startswith("account:") else "your address"
                raise RateLimited(
                    f"too many failed logins for {what}; try again in {int(retry) + 1} s",
                    retry_after_s=int(retry) + 1,
                )

    async def failed(self, account_key: str, addr: str | None, now: datetime) -> None:
        """Count one failure against the account and the address."""
        await self.repo.add([k for k, _ in self._keys(account_key, addr)], now)

    async def succeeded(self, account_key: str) -> None:
        """A successful login clears the account's failures (not the address's)."""
        await self.repo.clear(f"account:{account_key}")


class SessionService:
    """Opens, checks, renews and ends sessions."""

    def __init__(self, db: AsyncSession, settings: Settings) -> None:
        self.db = db
        self.settings = settings
        self.repo = SessionRepository(db)

    def _policy(self, kind: str) -> tuple[int, int]:
        s = self.settings
        return (
            (s.session_ttl_s, s.session_idle_s)
            if kind == "user"
            else (s.asset_session_ttl_s, s.asset_session_idle_s)
        )

    async def open(
        self, account: Account, *, force: bool, client_addr: str | None, via: str = "login"
    ) -> IssuedToken:
        """One live session per account: refuse with 409 while one is alive unless `force`."""
        now = utcnow()
        key = {"user_id": account.id} if account.kind == "user" else {"asset_id": account.id}
        existing = [s for s in await self.repo.open_for(**key) if s.alive_at(now)]
        if existing and not force:
            live = existing[0]
            raise Conflict(
                f"{account.label} already has a live session (started {live.created_at:%Y-%m-%d %H:%M:%S} UTC, "
                f'last active {live.last_seen_at:%H:%M:%S} UTC); log in with "force": true to end it',
                code="session_active",
                details={
                    "session_started_at": live.created_at.isoformat(),
                    "last_seen_at": live.last_seen_at.isoformat(),
                },
            )
        ended = []
        for old in existing:
            old.ended_at, old.end_reason = now, "taken_over"
            ended.append(old.id)
            await record(
                self.db,
                "session.taken_over",
                organization_id=account.organization_id,
                actor_kind=account.kind,
                actor_id=str(account.id),
                target=str(old.id),
                client_addr=client_addr,
                previous_client_addr=old.client_addr,
            )
        ttl, idle = self._policy(account.kind)
        token = new_token()
        session = AuthSession(
            token_hash=token_hash(token),
            principal_kind=account.kind,
            user_id=account.id if account.kind == "user" else None,
            asset_id=account.id if account.kind == "asset" else None,
            organization_id=account.organization_id,
            created_at=now,
            last_seen_at=now,
            expires_at=now + timedelta(seconds=ttl),
            idle_timeout_s=idle,
            client_addr=client_addr,
        )
        self.repo.add(session)
        await self.db.flush()
        await record(
            self.db,
            via,
            organization_id=account.organization_id,
            actor_kind=account.kind,
            actor_id=str(account.id),
            target=str(session.id),
            client_addr=client_addr,
            forced=bool(ended),
        )
        return IssuedToken(token, session, tuple(ended))

    async def authenticate(self, token: str) -> AuthSession:
        """The live session of a bearer token, its last activity refreshed; else Unauthorized."""
        session = await self.repo.by_token_hash(token_hash(token))
        now = utcnow()
        if session is None:
            raise Unauthorized("unknown token")
        if session.ended_at is not None:
            reason = {
                "taken_over": "another login took this session over",
                "logout": "the session was logged out",
                "credentials_rotated": "the asset's credentials were rotated",
            }.get(session.end_reason or "", "the session was ended")
            raise Unauthorized(f"session ended: {reason}", code="session_ended")
        if not session.alive_at(now):
            raise Unauthorized("session expired", code="session_expired")
        if (now - session.last_seen_at).total_seconds() >= 5:
            session.last_seen_at = now
        return session

    async def touch(self, session_id: uuid.UUID) -> bool:
        """Mark a session active (WebSocket heartbeats); False when it is no longer alive."""
        session = await self.repo.by_id(session_id)
        now = utcnow()
        if session is None or not session.alive_at(now):
            return False
        session.last_seen_at = now
        return True

    async def renew(self, session: AuthSession) -> str:
        """Give the session a new token and a new expiry; the old token stops working."""
        token = new_token()
        ttl, _ = self._policy(session.principal_kind)
        session.token_hash = token_hash(token)
        session.expires_at = utcnow() + timedelta(seconds=ttl)
        await self.db.flush()
        return token

    async def end(self, session: AuthSession, reason: str) -> None:
        """End a session now."""
        if session.ended_at is None:
            session.ended_at, session.end_reason = utcnow(), reason
            await self.db.flush()

    async def end_all_for_asset(self, asset_id: uuid.UUID, reason: str) -> list[uuid.UUID]:
        """End every open session of an asset (credentials rotated, asset deleted)."""
        ended = []
        for s in await self.repo.open_for(asset_id=asset_id):
            await self.end(s, reason)
            ended.append(s.id)
        return ended

    async def end_all_for_user(
        self, user_id: uuid.UUID, reason: str, organization_id: uuid.UUID | None = None
    ) -> list[uuid.UUID]:
        """End every open session of a user, optionally only those in one organisation."""
        ended = []
        for s in await self.repo.open_for(user_id=user_id):
            if organization_id is None or s.organization_id == organization_id:
                await self.end(s, reason)
                ended.append(s.id)
        return ended
