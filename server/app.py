"""The FastAPI application factory and its lifespan (engine, migrations, background services)."""

from __future__ import annotations

import asyncio
import logging
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager

from fastapi import Depends, FastAPI
from fastapi.middleware.cors import CORSMiddleware
from fastapi.middleware.gzip import GZipMiddleware
from sqlalchemy.ext.asyncio import AsyncSession, async_sessionmaker

from server import api_fields, migrate
from server.airspace.endpoints import router as airspace_router
from server.assets.endpoints import router as assets_router
from server.audit.endpoints import router as audit_router
from server.auth.endpoints import router as auth_router
from server.auth.limiter import LoginLimiter, housekeeping_loop
from server.commands.endpoints import router as commands_router
from server.config import Settings
from server.console.endpoints import console_router
from server.deps import services_of, set_services
from server.docs import OPENAPI_URL, docs_router
from server.health import router as health_router
from server.kit import gctune, metrics, openapi
from server.kit.bodylimit import LimitBody
from server.kit.db import make_engine, make_sessionmaker
from server.kit.errors import RejectNulBytes, install_error_handlers
from server.kit.query import known_query_only
from server.kit.security import Passwords
from server.missions.endpoints import router as missions_router
from server.organizations.endpoints import router as organizations_router
from server.realtime.broker import make_broker
from server.realtime.endpoints import router as realtime_router
from server.realtime.hub import Hub
from server.realtime.ingest import Ingest
from server.runs.endpoints import router as runs_router
from server.runs.engine import RunEngine
from server.schedules.endpoints import router as schedules_router
from server.schedules.service import Scheduler
from server.services import Services
from server.stations.caster import Caster
from server.stations.ntrip import ntrip_router
from server.stations.service import BaseCorrections, caster_authenticator, caster_recheck
from server.telemetry.bulk import OneTrip, PostgresOneTrip, SqliteOneTrip
from server.telemetry.endpoints import router as telemetry_router
from server.telemetry.sql import SqlTelemetryStore
from server.telemetry.store import TelemetryStore, retention_loop
from server.video.endpoints import router as video_router
from server.video.lifecycle import make_gateway
from server.video.page import router as video_page_router

log = logging.getLogger(__name__)
VERSION = "0.1.0"


def make_telemetry_store(
    settings: Settings, sessionmaker: async_sessionmaker[AsyncSession], dialect: str
) -> TelemetryStore:
    """InfluxDB when INFLUXDB_URL is set, else the SQL table."""
    if settings.influxdb_url:
        from server.telemetry.influx import InfluxTelemetryStore

        return InfluxTelemetryStore(settings.influxdb_url)
    return SqlTelemetryStore(sessionmaker, dialect)


def create_app(settings: Settings | None = None) -> FastAPI:
    """Build the application; nothing connects until its lifespan starts."""
    settings = settings or Settings()
    passwords = Passwords(
        settings.argon2_time_cost, settings.argon2_memory_kib, settings.argon2_parallelism
    )

    @asynccontextmanager
    async def lifespan(app: FastAPI) -> AsyncIterator[None]:
        path = settings.sqlite_path()
        if path is not None:
            path.parent.mkdir(parents=True, exist_ok=True)
        if settings.migrate_on_start:
            await asyncio.to_thread(migrate.upgrade, settings.database_url)
        in_memory = settings.database_url.startswith("sqlite") and path is None
        pool = {"pool_size": settings.db_pool_size, "max_overflow": settings.db_max_overflow}
        sqlite = settings.database_url.startswith("sqlite")  # SQLite keeps its own pool sizes
        engine = make_engine(settings.database_url, **({} if sqlite else pool))
        sessionmaker = make_sessionmaker(engine)
        broker = make_broker(settings.redis_url)
        await broker.start()
        # the ingest's writes and the telemetry store's reads go through small pools of their
        # own, except in an in-memory SQLite database, which another engine would not see. A
        # request holds a connection of the requests' pool while it reads telemetry: a read from
        # that same pool would wait for a second one, and a burst of reads (~30) would deadlock
        # the pool until its timeout, every other request of the process with it
        reads_engine = (
            engine if in_memory else make_engine(settings.database_url, pool_size=5, max_overflow=5)
        )
        telemetry = make_telemetry_store(
            settings, make_sessionmaker(reads_engine), engine.dialect.name
        )
        await telemetry.start()
        ingest_engine = (
            engine
            if in_memory
            # no pre-ping: a dead connection fails its batch (replayed) and is replaced
            else make_engine(
                settings.database_url, pool_size=2, max_overflow=0, pool_pre_ping=False
            )
        )
        # plain telemetry batches in one trip (bulk.py); in-memory SQLite has one connection only
        one_trip: OneTrip | None = None
        if path is not None:
            one_trip = SqliteOneTrip(str(path), engine.dialect)
        elif engine.dialect.name == "postgresql":
            one_trip = PostgresOneTrip(ingest_engine)
        ingest = Ingest(
            sessionmaker, telemetry, writer=make_sessionmaker(ingest_engine), one_trip=one_trip
        )
        ingest.start()
        hub = Hub(broker, sessionmaker, command_sweep_s=settings.command_sweep_s)
        await hub.start()
        metrics.watch_hub(hub)
        video = make_gateway(settings)
        caster = None
        if settings.ntrip_port is not None:
            caster = Caster(
                BaseCorrections(lambda: services),
                caster_authenticator(lambda: services),
                proxy_protocol=settings.ntrip_proxy_protocol,
                recheck=caster_recheck(lambda: services),
                recheck_s=settings.ntrip_recheck_s,
            )
        services = Services(
            settings=settings,
            passwords=passwords,
            engine=engine,
            sessionmaker=sessionmaker,
            broker=broker,
            telemetry=telemetry,
            ingest=ingest,
            hub=hub,
            limiter=LoginLimiter(sessionmaker, settings),
            session_end_listeners=(hub.sessions_ended,),
            video=video,
            ntrip=caster,
        )
        set_services(app, services)
        if caster is not None:  # NTRIP 1 clients, which the HTTP port cannot serve
            await caster.start(settings.host, settings.ntrip_port or 0)
        runs = RunEngine(services, hub.node)
        scheduler = Scheduler(services, grace_s=settings.schedule_grace_s)
        if settings.run_engine:
            runs.start()
            scheduler.start()
        retention = asyncio.create_task(
            retention_loop(telemetry, settings.telemetry_retention_days)
        )
        login_housekeeping = asyncio.create_task(housekeeping_loop(sessionmaker, settings))
        log.info(
            "server started", extra={"database": engine.url.render_as_string(hide_password=True)}
        )
        try:
            with gctune.tuned(settings.gc_tuned):
                yield
        finally:
            retention.cancel()
            login_housekeeping.cancel()
            if caster is not None:
                await caster.close()
            await video.close()
            await scheduler.stop()
            await runs.stop()
            await hub.stop()
            await ingest.stop()
            if one_trip is not None:
                await one_trip.close()
            await telemetry.close()
            await broker.close()
            for own in {ingest_engine, reads_engine} - {engine}:
                await own.dispose()
            await engine.dispose()

    app = FastAPI(
        title="Aerobase",
        version=VERSION,
        lifespan=lifespan,
        openapi_url=OPENAPI_URL,
        docs_url=None,  # server/docs.py: the same page, its files from this server
        redoc_url=None,
        description="REST API of the Aerobase drone-in-a-box platform. See frontend_api.md.",
        # `/path/` answers 404 rather than a 307 to an absolute http:// URL (wrong behind TLS)
        redirect_slashes=False,
        dependencies=[Depends(known_query_only)],
        generate_unique_id_function=openapi.operation_id,
    )
    # the last added runs first: CORS headers go on every answer, refusals included
    app.add_middleware(GZipMiddleware, minimum_size=2048)
    app.add_middleware(
        LimitBody,
        default=settings.max_body_bytes,
        routes={"/api/v1/missions/import": settings.max_import_bytes},
    )
    app.add_middleware(RejectNulBytes)
    app.add_middleware(metrics.ObserveRequests)
    if settings.cors_origins:
        app.add_middleware(
            CORSMiddleware,
            allow_origins=settings.cors_origins,
            allow_methods=["GET", "POST", "PUT", "PATCH", "DELETE"],
            allow_headers=["Authorization", "Content-Type", "If-Match", "If-None-Match"],
            expose_headers=[
                "Content-Disposition",
                "ETag",
                "Link",
                "Location",
                "Retry-After",
                "X-Request-Id",
                "X-Total-Count",
            ],
            max_age=600,
        )
    install_error_handlers(app)
    for router in (
        health_router,
        auth_router,
        organizations_router,
        assets_router,
        audit_router,
        commands_router,
        telemetry_router,
        realtime_router,
        missions_router,
        airspace_router,
        runs_router,
        schedules_router,
        video_router,
        video_page_router,
    ):
        app.include_router(router)
    app.include_router(console_router(tile_url=settings.map_tile_url))
    app.include_router(docs_router(app.title))

    openapi.install(app, api_fields.FIELDS, api_fields.OVERRIDES)

    # the caster's router exists before the lifespan builds the services: it reads them per request
    def services() -> Services:
        return services_of(app)

    # NTRIP is its own protocol (basic auth, gnss/* content types): served beside the REST API
    app.include_router(
        ntrip_router(
            BaseCorrections(services),
            caster_authenticator(services),
            recheck=caster_recheck(services),
            recheck_s=settings.ntrip_recheck_s,
        ),
        include_in_schema=False,
    )
    return app
