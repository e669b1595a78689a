"""A user changing their own password: the current one is checked as a login checks it (the
failed-login limits, the wrong guesses already seen), the new one is hashed, and every other
session of the user ends (a password changed because it leaked must cut off whoever used it)."""

from __future__ import annotations

import asyncio

from server.audit.service import record
from server.auth.limiter import LoginLimiter
from server.auth.models import AuthSession
from server.auth.service import SessionService
from server.config import Settings
from server.kit.errors import Forbidden, Unprocessable
from server.kit.principal import Principal
from server.kit.security import Passwords
from server.kit.time import utcnow
from server.kit.uow import UnitOfWork
from server.organizations.models import User


class WrongPassword(Unprocessable):
    """The current password given is not the caller's. Its failed attempt is written in the
    request's transaction: the route answers it without raising, so that it is committed."""

    code = "wrong_password"

    def __init__(self) -> None:
        super().__init__("the current password is wrong")


DOOR = "password_change"  # on /metrics (aerobase_logins_total)


class PasswordService:
    """Changes the caller's own password."""

    def __init__(
        self, uow: UnitOfWork, settings: Settings, passwords: Passwords, limiter: LoginLimiter
    ) -> None:
        self.uow, self.settings, self.passwords, self.limiter = uow, settings, passwords, limiter

    async def change(
        self, principal: Principal, session: AuthSession, current: str, new: str
    ) -> int:
        """Replace the caller's password; how many of their other sessions ended. A wrong
        `current` counts as a failed login of the account from the caller's address (429 past
        the limit), so a stolen session cannot guess its way to the password: `WrongPassword`,
        which the route answers without raising, so that the attempt is committed."""
        if principal.kind != "user" or principal.user_id is None:
            raise Forbidden(
                "an asset has no password: reissue its configuration to rotate its secret",
                code="not_a_user",
            )
        if new == current:  # said before any check: it tells nothing of the password
            raise Unprocessable("the new password is the current one", code="same_password")
        user = await self.uow.db.get(User, principal.user_id, with_for_update=True)
        assert user is not None  # the session's user: a deleted user has no live session
        addr = self.uow.client_addr
        if self.limiter.repeated(DOOR, user.email, addr, current, user.password_hash):
            raise WrongPassword()
        # in the request's transaction: it holds a connection already (see admit_in)
        attempt = await self.limiter.admit_in(self.uow.db, user.email, addr, utcnow(), door=DOOR)
        if not await asyncio.to_thread(self.passwords.verify, user.password_hash, current):
            self.limiter.wrong(DOOR, user.email, addr, current, user.password_hash)
            raise WrongPassword()
        await self.limiter.succeeded(self.uow.db, user.email, addr, attempt)
        self.limiter.outcome(DOOR, "ok")
        user.password_hash = await asyncio.to_thread(self.passwords.hash, new)
        ended = await SessionService(self.uow, self.settings).end_all_for_user(
            user.id, "password_changed", keep=session.id
        )
        await record(
            self.uow, principal, "user.password_changed", target=user.email, sessions=len(ended)
        )
        return len(ended)
