"""The landing-base domain: NTRIP mountpoints from bases, caster authentication, corrections."""

from __future__ import annotations

import asyncio
import functools
import hmac
import secrets
import uuid
from collections.abc import AsyncIterator, Awaitable, Callable

from server.kit.errors import RateLimited
from server.kit.time import utcnow
from server.kit.uow import unit_of_work
from server.organizations.repository import UserRepository
from server.realtime.channels import rtcm_channel
from server.services import Services
from server.stations.ntrip import Mountpoint, broker_frames, format_details, mountpoint_name
from server.stations.repository import all_bases


class BaseCorrections:
    """One NTRIP mountpoint per landing base, fed by the broker channel its daemon publishes to."""

    def __init__(self, services: Callable[[], Services]) -> None:
        """`services` returns the running app's services (they exist once its lifespan started)."""
        self.services = services

    async def mountpoints(self) -> list[Mountpoint]:
        """A mountpoint for every landing base (position from its attributes when surveyed)."""
        async with self.services().sessionmaker() as db:
            bases = await all_bases(db)
        out = []
        for base in bases:
            attrs = base.attributes or {}
            out.append(
                Mountpoint(
                    name=mountpoint_name(base.name),
                    identifier=base.name[:60],
                    format_details=format_details({1005: 1, 1077: 1, 1097: 1, 1230: 1}),
                    latitude=float(attrs.get("latitude", 0.0) or 0.0),
                    longitude=float(attrs.get("longitude", 0.0) or 0.0),
                    organisation_id=base.organization_id,
                    asset_id=base.id,
                )
            )
        return out

    def subscribe(self, mountpoint: Mountpoint) -> AsyncIterator[bytes]:
        """Live frames of the base behind `mountpoint`."""
        return broker_frames(
            self.services().broker, rtcm_channel(uuid.UUID(str(mountpoint.asset_id)))
        )


def caster_authenticator(
    services: Callable[[], Services],
) -> Callable[[str, str, str | None], Awaitable[uuid.UUID | None]]:
    """`authenticate(username, password, address)` for the caster: a user's e-mail and password
    -> organisation; failures count against the account and the caller's address, as logins do.

    Rovers often share one account, and reconnect together when a caster restarts: requests
    with the same credentials while one is being checked wait for that check instead of each
    costing a password hash and a place under the account's failed-login limit (which would turn
    the sixth of them into a 401). Once the check is answered, only a wrong password is
    remembered, per address, by the limiter (`server/auth/guesses.py`): a rover retrying it is
    answered 401 at once and not counted again."""
    under_way: dict[tuple[str, bytes], asyncio.Task[uuid.UUID | None]] = {}
    key = secrets.token_bytes(32)  # the credentials' in-flight key: never the password itself

    def done(which: tuple[str, bytes], task: asyncio.Task[uuid.UUID | None]) -> None:
        under_way.pop(which, None)
        if not task.cancelled():
            task.exception()  # retrieved here: every waiter may have gone

    async def authenticate(username: str, password: str, address: str | None) -> uuid.UUID | None:
        which = (username, hmac.digest(key, password.encode(), "sha256"))
        task = under_way.get(which)
        if task is None:  # the check runs on its own: a waiter leaving does not cancel it
            task = under_way[which] = asyncio.create_task(check(username, password, address))
            task.add_done_callback(functools.partial(done, which))
        return await asyncio.shield(task)

    async def check(username: str, password: str, address: str | None) -> uuid.UUID | None:
        state = services()
        limiter = state.limiter
        async with unit_of_work(state.sessionmaker) as uow:  # "\x00": no e-mail, nothing to read
            user = (
                await UserRepository(uow.db).by_email(username) if "\x00" not in username else None
            )
        stored = user.password_hash if user else None
        if limiter.repeated("ntrip", username, address, password, stored):
            return None  # a rover retrying a stale password: not counted again
        try:
            attempt = await limiter.admit(username, address, utcnow(), door="ntrip")
        except RateLimited:
            return None
        # the hash checked with no connection held: argon2 takes its time
        if not await asyncio.to_thread(state.passwords.verify, stored, password) or user is None:
            limiter.wrong("ntrip", username, address, password, stored)
            return None  # the attempt stays counted as a failure
        async with unit_of_work(state.sessionmaker) as uow:
            await limiter.succeeded(uow.db, username, address, attempt)
            limiter.verified.remember(username, None, password, stored)
            limiter.outcome("ntrip", "ok")
            if not user.is_active:
                return None
            memberships = await UserRepository(uow.db).memberships(user.id)
        active = [o.id for m, o in memberships if m.is_active]
        return active[0] if active else None

    return authenticate


def caster_recheck(
    services: Callable[[], Services],
) -> Callable[[str, str, uuid.UUID], Awaitable[bool]]:
    """`recheck(username, password, organisation)` for streams: whether that user is still
    active, an active member of the organisation the stream was opened for, and the password
    still theirs. The password is verified again only when the account's hash has changed since
    it last matched (`LoginLimiter.verified`): a query per check, a password hash per change."""

    async def still(username: str, password: str, organisation_id: uuid.UUID) -> bool:
        state = services()
        async with unit_of_work(state.sessionmaker) as uow:
            users = UserRepository(uow.db)
            user = await users.by_email(username)
            if user is None or not user.is_active:
                return False
            memberships = await users.memberships(user.id)
        if not any(o.id == organisation_id and m.is_active for m, o in memberships):
            return False
        verified, stored = state.limiter.verified, user.password_hash
        if verified.known(username, None, password, stored):
            return True
        if not await asyncio.to_thread(state.passwords.verify, stored, password):
            return False  # changed or reset: this stream's password is no longer the account's
        verified.remember(username, None, password, stored)
        return True

    return still
