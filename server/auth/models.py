"""Tables of sessions, failed login attempts and the clients known to have logged in."""

from __future__ import annotations

import uuid
from datetime import datetime

from sqlalchemy import ForeignKey, Index, PrimaryKeyConstraint, String, text
from sqlalchemy.orm import Mapped, mapped_column

from server.kit.db import Base, IdMixin
from server.kit.time import utcnow

# a session is open until it is ended (`ended_at`), expired or not
OPEN = text("ended_at IS NULL")


def one_open_session(column: str) -> Index:
    """At most one open session per account: the database's own rule (PostgreSQL and SQLite
    alike), whatever path opens one and however many do so at once."""
    return Index(
        f"ux_auth_sessions_{column}_open",
        column,
        unique=True,
        postgresql_where=OPEN,
        sqlite_where=OPEN,
    )


class AuthSession(IdMixin, Base):
    """One login of a user or an asset; the token is stored only as its hash. An account has at
    most one open session: opening one ends the others (`SessionService.open`)."""

    __tablename__ = "auth_sessions"
    __table_args__ = (
        Index("ix_auth_sessions_user_live", "user_id", "ended_at"),
        Index("ix_auth_sessions_asset_live", "asset_id", "ended_at"),
        one_open_session("user_id"),
        one_open_session("asset_id"),
    )

    token_hash: Mapped[str] = mapped_column(String(64), unique=True)
    principal_kind: Mapped[str] = mapped_column(String(8))  # "user" | "asset"
    user_id: Mapped[uuid.UUID | None] = mapped_column(ForeignKey("users.id", ondelete="CASCADE"))
    asset_id: Mapped[uuid.UUID | None] = mapped_column(ForeignKey("assets.id", ondelete="CASCADE"))
    organization_id: Mapped[uuid.UUID | None] = mapped_column(
        ForeignKey("organizations.id", ondelete="CASCADE")
    )
    created_at: Mapped[datetime] = mapped_column(default=utcnow)
    last_seen_at: Mapped[datetime] = mapped_column(default=utcnow)
    expires_at: Mapped[datetime]
    idle_timeout_s: Mapped[int]
    ended_at: Mapped[datetime | None] = mapped_column(default=None)
    end_reason: Mapped[str | None] = mapped_column(String(32), default=None)
    client_addr: Mapped[str | None] = mapped_column(String(64), default=None)

    def alive_at(self, now: datetime) -> bool:
        """True while not ended, not expired and not idle for too long."""
        if self.ended_at is not None or now >= self.expires_at:
            return False
        return (now - self.last_seen_at).total_seconds() < self.idle_timeout_s


class LoginFailure(IdMixin, Base):
    """One failed login, counted against an account and against a client address."""

    __tablename__ = "login_failures"
    __table_args__ = (Index("ix_login_failures_key_at", "key", "at"),)

    key: Mapped[str] = mapped_column(String(400))  # "account:<email|asset name>" or "addr:<ip>"
    at: Mapped[datetime] = mapped_column(default=utcnow)


class KnownLoginClient(Base):
    """An address from which an account last gave the right password, and when. Failed logins
    from there count against the account at that address, not the account as a whole, so that
    wrong passwords sent from anywhere else cannot lock it out (server/auth/limiter.py)."""

    __tablename__ = "login_known_clients"
    __table_args__ = (PrimaryKeyConstraint("account_key", "addr"),)

    account_key: Mapped[str] = mapped_column(String(320))  # an e-mail, as logins name it
    addr: Mapped[str] = mapped_column(String(64))
    last_success_at: Mapped[datetime] = mapped_column(default=utcnow, index=True)
