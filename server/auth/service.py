"""Decisions about sessions: one live session per account, tokens, how sessions end."""

from __future__ import annotations

import uuid
from dataclasses import dataclass
from datetime import datetime, timedelta

from sqlalchemy.exc import IntegrityError
from sqlalchemy.ext.asyncio import AsyncSession

from server.audit.service import record
from server.auth.models import AuthSession
from server.auth.repository import SessionRepository
from server.config import Settings
from server.kit.errors import Conflict, Unauthorized
from server.kit.principal import Principal
from server.kit.security import new_token, token_hash
from server.kit.time import rfc3339, utcnow
from server.kit.uow import UnitOfWork

# why a session ended, as stored (`end_reason`) and as told to its token and its sockets
END_REASONS = {
    "taken_over": "another login took this session over",
    "logout": "the session was logged out",
    "credentials_rotated": "the asset's credentials were rotated",
    "asset_deleted": "the asset was deleted",
    "disabled": "the account was disabled",
    "removed": "the user was removed from the organisation",
    "password_changed": "the account's password was changed",
    "password_reset": "the account's password was reset by an administrator",
    "expired": "the session expired",  # found past its expiry by the account's next login
}


def _session_active(account: Account, live: AuthSession) -> Conflict:
    return Conflict(
        f"{account.label} already has a live session (started "
        f"{rfc3339(live.created_at.replace(microsecond=0))}, last active "
        f'{rfc3339(live.last_seen_at.replace(microsecond=0))}); log in with "force": true '
        "to end it",
        code="session_active",
        details={
            "session_started_at": rfc3339(live.created_at),
            "last_seen_at": rfc3339(live.last_seen_at),
        },
    )


@dataclass(frozen=True)
class Account:
    """The account a login is for: a user (with the organisation chosen) or an asset."""

    kind: str  # "user" | "asset"
    id: uuid.UUID
    organization_id: uuid.UUID | None
    label: str

    def principal(self, session_id: uuid.UUID) -> Principal:
        """The account as the caller of its new session (for the audit log)."""
        return Principal(
            kind=self.kind,
            session_id=session_id,
            organization_id=self.organization_id,
            user_id=self.id if self.kind == "user" else None,
            asset_id=self.id if self.kind == "asset" else None,
            label=self.label,
        )


@dataclass(frozen=True)
class IssuedToken:
    """A freshly issued bearer token and its session."""

    access_token: str
    session: AuthSession
    ended_sessions: tuple[uuid.UUID, ...]


class SessionService:
    """Opens, checks, renews and ends sessions; every end is announced after commit.

    Auth runs before there is a caller, so this service takes the unit of work and the settings
    where the others take the unit of work and the principal."""

    def __init__(self, uow: UnitOfWork, settings: Settings) -> None:
        self.uow = uow
        self.db = uow.db
        self.settings = settings
        self.repo = SessionRepository(uow.db)

    def _policy(self, kind: str) -> tuple[int, int]:
        s = self.settings
        return (
            (s.session_ttl_s, s.session_idle_s)
            if kind == "user"
            else (s.asset_session_ttl_s, s.asset_session_idle_s)
        )

    async def open(self, account: Account, *, force: bool, via: str = "login") -> IssuedToken:
        """One live session per account: refuse with 409 while one is alive unless `force`.

        Every open session of the account is ended before the new one is added (a live one is
        taken over, one past its expiry or idle timeout is ended as expired), so an account never
        has two open sessions, and the database's partial unique index (`one_open_session`)
        refuses a second on every backend. Concurrent logins of one account take turns when the
        caller has claimed the account first (`LoginService`: a conditional write on its row),
        so that what is read here is current; one that lost a race with another open anyway is
        answered 409 `session_active`, as if it had seen that session."""
        now = utcnow()
        key = {"user_id": account.id} if account.kind == "user" else {"asset_id": account.id}
        open_now = await self.repo.open_for(**key)
        live = [s for s in open_now if s.alive_at(now)]
        if live and not force:
            raise _session_active(account, live[0])
        for stale in open_now:
            if not stale.alive_at(now):
                await self.end(stale, "expired")
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
            client_addr=self.uow.client_addr,
        )
        for old in live:
            await self.end(old, "taken_over")
        self.repo.add(session)
        try:
            await self.db.flush()
        except IntegrityError as err:  # another open of this account committed first
            raise Conflict(
                f"{account.label} already has a live session (opened by another login at the "
                'same moment); log in with "force": true to end it',
                code="session_active",
            ) from err
        actor = account.principal(session.id)
        for old in live:
            await record(
                self.uow,
                actor,
                "session.taken_over",
                target=str(old.id),
                previous_client_addr=old.client_addr,
            )
        await record(self.uow, actor, via, target=str(session.id), forced=bool(live))
        return IssuedToken(token, session, tuple(old.id for old in live))

    async def authenticate(self, token: str) -> AuthSession:
        """The live session of a bearer token, its last activity refreshed; else Unauthorized."""
        session = await self.repo.by_token_hash(token_hash(token))
        now = utcnow()
        if session is None:
            raise Unauthorized("unknown token")
        if session.end_reason == "expired" or (
            session.ended_at is None and not session.alive_at(now)
        ):
            raise Unauthorized("session expired", code="session_expired")
        if session.ended_at is not None:
            reason = END_REASONS.get(session.end_reason or "", "the session was ended")
            raise Unauthorized(f"session ended: {reason}", code="session_ended")
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
        """Give the session a new token and a new expiry; the old token and its sockets stop."""
        token = new_token()
        ttl, _ = self._policy(session.principal_kind)
        session.token_hash = token_hash(token)
        session.expires_at = utcnow() + timedelta(seconds=ttl)
        await self.db.flush()
        self.uow.sessions_ended([session.id], "renewed: connect again with the new token")
        return token

    async def end(self, session: AuthSession, reason: str) -> None:
        """End a session now; its sockets close once the unit of work commits."""
        if session.ended_at is None:
            session.ended_at, session.end_reason = utcnow(), reason
            await self.db.flush()
            self.uow.sessions_ended([session.id], END_REASONS.get(reason, reason))

    async def end_all_for_asset(self, asset_id: uuid.UUID, reason: str) -> list[uuid.UUID]:
        """End every open session of an asset (credentials rotated, asset deleted)."""
        ended = []
        for s in await self.repo.open_for(asset_id=asset_id):
            await self.end(s, reason)
            ended.append(s.id)
        return ended

    async def end_all_for_user(
        self,
        user_id: uuid.UUID,
        reason: str,
        organization_id: uuid.UUID | None = None,
        *,
        keep: uuid.UUID | None = None,
    ) -> list[uuid.UUID]:
        """End every open session of a user, optionally only those in one organisation, and
        but the one `keep` names."""
        ended = []
        for s in await self.repo.open_for(user_id=user_id):
            if s.id == keep:
                continue
            if organization_id is None or s.organization_id == organization_id:
                await self.end(s, reason)
                ended.append(s.id)
        return ended


async def alive_until(
    db: AsyncSession, ids: list[uuid.UUID], now: datetime
) -> dict[uuid.UUID, datetime | None]:
    """For each session: until when it stays alive without further activity (None: not alive)."""
    out: dict[uuid.UUID, datetime | None] = dict.fromkeys(ids)
    for session in await SessionRepository(db).by_ids(ids):
        if session.alive_at(now):
            idle_end = session.last_seen_at + timedelta(seconds=session.idle_timeout_s)
            out[session.id] = min(session.expires_at, idle_end)
    return out


async def touch_many(db: AsyncSession, ids: list[uuid.UUID], now: datetime) -> set[uuid.UUID]:
    """Heartbeats of many sessions at once (a process's asset sockets): those still alive are
    marked seen now (one read, one UPDATE per 500); returns their ids."""
    alive: set[uuid.UUID] = set()
    repo = SessionRepository(db)
    for start in range(0, len(ids), 500):
        chunk = ids[start : start + 500]
        seen = [s.id for s in await repo.by_ids(chunk) if s.alive_at(now)]
        await repo.mark_seen(seen, now)
        alive.update(seen)
    return alive
