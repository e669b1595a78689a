"""The server's long-lived services, built once in the app's lifespan and handed to whoever needs them.

Background loops (run engine, scheduler, NTRIP relay) take this object in their constructor and
routes reach it through one dependency (`server.deps.ServicesDep`), so what each part uses shows
in its imports instead of hiding in an untyped `app.state`.
"""

from __future__ import annotations

from dataclasses import dataclass

from sqlalchemy.ext.asyncio import AsyncEngine, AsyncSession, async_sessionmaker

from server.auth.limiter import LoginLimiter
from server.config import Settings
from server.kit.security import Passwords
from server.kit.uow import SessionEndListener
from server.realtime.broker import Broker
from server.realtime.hub import Hub
from server.realtime.ingest import Ingest
from server.stations.caster import Caster
from server.telemetry.store import TelemetryStore
from server.video.gateway import MediaGateway


@dataclass(frozen=True)
class Services:
    """Everything a request, a socket or a background loop may use; one per running app."""

    settings: Settings
    passwords: Passwords
    engine: AsyncEngine
    sessionmaker: async_sessionmaker[AsyncSession]
    broker: Broker
    telemetry: TelemetryStore
    ingest: Ingest
    hub: Hub
    limiter: LoginLimiter  # failed-login limits, and the wrong passwords already checked
    session_end_listeners: tuple[SessionEndListener, ...] = ()
    video: MediaGateway | None = None  # the live-video media path (server/video)
    ntrip: Caster | None = None  # the caster's own port (AEROBASE_NTRIP_PORT), started after this
