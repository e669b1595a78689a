"""The landing-base domain: NTRIP mountpoints from bases, caster authentication, corrections."""

from __future__ import annotations

import asyncio
import uuid
from collections.abc import AsyncIterator
from typing import Any

from server.config import Settings
from server.kit.errors import RateLimited
from server.kit.time import utcnow
from server.organizations.repository import UserRepository
from server.stations.ntrip import Mountpoint, broker_frames, format_details, mountpoint_name
from server.stations.repository import all_bases


class BaseCorrections:
    """One NTRIP mountpoint per landing base, fed by the broker channel its daemon publishes to."""

    def __init__(self, state: Any) -> None:
        self.state = (
            state  # the app's state: sessionmaker and broker exist once the app has started
        )

    async def mountpoints(self) -> list[Mountpoint]:
        """A mountpoint for every landing base (position from its attributes when surveyed)."""
        async with self.state.sessionmaker() as db:
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
        return broker_frames(self.state.broker, f"rtcm.{mountpoint.asset_id}")


def caster_authenticator(state: Any, settings: Settings):  # type: ignore[no-untyped-def]
    """`authenticate(username, password)` for the caster: a user's e-mail and password -> organisation."""
    from server.auth.service import RateLimiter

    async def authenticate(username: str, password: str) -> uuid.UUID | None:
        async with state.sessionmaker() as db:
            limiter = RateLimiter(db, settings)
            try:
                await limiter.check(username, None, utcnow())
            except RateLimited:
                return None
            users = UserRepository(db)
            user = await users.by_email(username) if "\x00" not in username else None
            ok = await asyncio.to_thread(
                state.passwords.verify, user.password_hash if user else None, password
            )
            if not ok or user is None or not user.is_active:
                await limiter.failed(username, None, utcnow())
                await db.commit()
                return None
            memberships = await users.memberships(user.id)
            return memberships[0][1].id if memberships else None

    return authenticate
