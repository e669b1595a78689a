"""`aerobase server` and `aerobase admin ...`: serve, migrate, bootstrap organisations and users."""

from __future__ import annotations

import argparse
import asyncio
import functools
import getpass
import logging
import os
import sys
from collections.abc import AsyncIterator, Sequence
from contextlib import asynccontextmanager
from typing import Any

from sqlalchemy import make_url
from sqlalchemy.exc import DBAPIError

from server import migrate
from server.auth.service import Account, SessionService
from server.config import Settings
from server.kit.db import make_engine, make_sessionmaker
from server.kit.errors import AppError
from server.kit.http_head import HeadTimeoutProtocol
from server.kit.principal import Role
from server.kit.security import Passwords
from server.kit.uow import SessionEndListener, UnitOfWork
from server.logging import configure_logging
from server.organizations import service
from server.organizations.repository import UserRepository
from server.realtime.broker import RedisBroker
from server.realtime.hub import RECHECK_S, announce_sessions_ended
from server.realtime.native import WebSocketProtocol

log = logging.getLogger(__name__)


def server_main(argv: Sequence[str] | None = None) -> int:
    """`aerobase server [--host H] [--port P] [--workers N]`: migrate, then serve (on uvloop)."""
    import uvicorn

    from server.app import create_app

    parser = argparse.ArgumentParser(prog="aerobase server")
    parser.add_argument("--host", default=None)
    parser.add_argument("--port", type=int, default=None)
    parser.add_argument(
        "--workers",
        type=int,
        default=1,
        help="server processes sharing the port (default 1); more than one needs REDIS_URL, "
        "which carries presence and fan-out between them",
    )
    args = parser.parse_args(argv)
    overrides = {k: v for k, v in (("host", args.host), ("port", args.port)) if v is not None}
    settings = Settings(**overrides)
    configure_logging(settings.log_format, settings.log_level)
    if args.workers < 1:
        parser.error("--workers must be at least 1")
    if args.workers == 1:
        uvicorn.run(create_app(settings), **uvicorn_options(settings))
        return 0
    if not settings.redis_url:
        parser.error(
            "--workers above 1 needs REDIS_URL: an asset and its operators may be served by "
            "different processes, and only the Redis broker reaches across them"
        )
    # migrated once here, not by every worker at the same time
    migrate.upgrade(settings.database_url)
    os.environ["AEROBASE_MIGRATE_ON_START"] = "false"
    os.environ["AEROBASE_HOST"], os.environ["AEROBASE_PORT"] = settings.host, str(settings.port)
    uvicorn.run(
        "server.cli:worker_app", factory=True, workers=args.workers, **uvicorn_options(settings)
    )
    return 0


def worker_app() -> Any:
    """The app of one `--workers` process (each configures its own structured logs)."""
    from server.app import create_app

    settings = Settings()
    configure_logging(settings.log_format, settings.log_level)
    return create_app(settings)


def uvicorn_options(settings: Settings) -> dict[str, Any]:
    """How uvicorn serves the app: frames over 1 MiB close with 1009, a peer that does not
    answer the server's pings (every ws_ping_interval_s) within ws_ping_timeout_s is dropped, and
    an idle HTTP connection is held http_keep_alive_s (uvicorn's own default, 5 s, is below any
    proxy's upstream keep-alive)."""
    return {
        "host": settings.host,
        "port": settings.port,
        "log_config": None,
        "timeout_keep_alive": settings.http_keep_alive_s,
        # /ws/asset and /ws/operator served straight from the transport (server/realtime/native.py)
        "ws": WebSocketProtocol,
        "ws_max_size": 1 << 20,
        "ws_per_message_deflate": False,
        "ws_ping_interval": settings.ws_ping_interval_s,
        "ws_ping_timeout": settings.ws_ping_timeout_s,
        # an HTTP request head (a WebSocket upgrade's too) is due within http_header_timeout_s
        "http": HeadTimeoutProtocol,
        # X-Forwarded-For believed from the reverse proxy's own address(es) only
        "proxy_headers": True,
        "forwarded_allow_ips": settings.forwarded_allow_ips,
        # explicit, not uvicorn's "auto" (which silently falls back to asyncio's loop, ~27 % more
        # CPU per message on the telemetry path)
        "loop": "uvloop" if _has_uvloop() else "asyncio",
    }


def _has_uvloop() -> bool:
    try:
        import uvloop  # noqa: F401
    except ImportError:  # a platform without it (Windows): a dependency everywhere else
        return False
    return True


def _password(given: str | None, env: str = "AEROBASE_PASSWORD") -> str:
    if given:
        return given
    if os.environ.get(env):
        return os.environ[env]
    if not sys.stdin.isatty():
        raise AppError(
            f"no password: give --password, set {env}, or run on a terminal to be prompted"
        )
    first = getpass.getpass("Password: ")
    if first != getpass.getpass("Repeat password: "):
        raise AppError("the passwords differ")
    return first


async def _with_db(settings: Settings, fn):  # type: ignore[no-untyped-def]
    engine = make_engine(settings.database_url)
    try:
        async with make_sessionmaker(engine)() as db:
            result = await fn(db)
            await db.commit()
            return result
    finally:
        await engine.dispose()


def admin_main(argv: Sequence[str] | None = None) -> int:
    """`aerobase admin migrate|create-org|create-user|create-superuser|set-password|token`."""
    parser = argparse.ArgumentParser(prog="aerobase admin")
    sub = parser.add_subparsers(dest="command", required=True)
    sub.add_parser("migrate", help="apply database migrations")
    p = sub.add_parser("create-org", help="create an organisation; prints its id")
    p.add_argument("name")
    p = sub.add_parser("create-user", help="create a user in an organisation")
    p.add_argument("--org", required=True)
    p.add_argument("--email", required=True)
    p.add_argument("--role", required=True, choices=[r.value for r in Role])
    p.add_argument("--password")
    p = sub.add_parser("create-superuser", help="create a platform superuser")
    p.add_argument("--email", required=True)
    p.add_argument("--password")
    p = sub.add_parser(
        "set-password", help="give a user a new password and end every session of theirs"
    )
    p.add_argument("--email", required=True)
    p.add_argument("--password")
    p = sub.add_parser("token", help="print a session token for scripts")
    p.add_argument("--email", required=True)
    p.add_argument("--org", help="organisation to act in (default: the user's first)")
    p.add_argument("--force", action="store_true", help="end the user's live session if any")
    args = parser.parse_args(argv)

    settings = Settings()
    configure_logging(settings.log_format, "WARNING")
    path = settings.sqlite_path()
    if path is not None:
        path.parent.mkdir(parents=True, exist_ok=True)
    try:
        migrate.upgrade(settings.database_url)
        if args.command == "migrate":
            print("database is at the latest migration")
            return 0
        passwords = Passwords(
            settings.argon2_time_cost, settings.argon2_memory_kib, settings.argon2_parallelism
        )
        result = asyncio.run(_with_db(settings, lambda db: _admin(db, args, settings, passwords)))
        print(result)
        return 0
    except AppError as err:
        print(f"aerobase admin {args.command}: {err.message}", file=sys.stderr)
        return 1
    except (OSError, DBAPIError) as err:  # the database refused, is away, or has no such database
        where = make_url(settings.database_url).render_as_string(hide_password=True)
        said = getattr(err, "orig", None) or err
        print(f"aerobase admin {args.command}: the database {where}: {said}", file=sys.stderr)
        return 1


async def _admin(db, args, settings: Settings, passwords: Passwords) -> str:  # type: ignore[no-untyped-def]
    if args.command == "create-org":
        return str((await service.create_organization(db, args.name)).id)
    if args.command == "create-user":
        org = await service.org_by_name(db, args.org)
        users = UserRepository(db)
        user = await users.by_email(args.email)
        if user is None:
            user = await service.create_user(
                db, passwords, email=args.email, password=_checked(_password(args.password))
            )
        elif any(o.id == org.id for _, o in await users.memberships(user.id)):
            raise AppError(f"{args.email} is already a member of {args.org}")
        await service.add_member(db, org.id, user.id, Role(args.role))
        return str(user.id)
    if args.command == "create-superuser":
        user = await service.create_user(
            db,
            passwords,
            email=args.email,
            password=_checked(_password(args.password)),
            is_superuser=True,
        )
        return str(user.id)
    if args.command == "set-password":  # the way back in for a superuser, or anyone, from a shell
        user = await UserRepository(db).by_email(args.email, lock=True)
        if user is None:
            raise AppError(f"no user with e-mail {args.email}")
        user.password_hash = passwords.hash(_checked(_password(args.password)))
        async with _session_end_announcer(settings) as listeners:
            uow = UnitOfWork(db, session_end_listeners=listeners)
            ended = await SessionService(uow, settings).end_all_for_user(user.id, "password_reset")
            await uow.commit()  # then the listeners tell the running servers
        sockets = (
            "the servers told to close their sockets"
            if listeners
            else f"their sockets close within {RECHECK_S:.0f} s"
        )
        return f"password of {user.email} set; {len(ended)} session(s) ended, {sockets}"
    if args.command == "token":
        users = UserRepository(db)
        user = await users.by_email(args.email)
        if user is None:
            raise AppError(f"no user with e-mail {args.email}")
        memberships = await users.memberships(user.id)
        orgs = [o for _, o in memberships if args.org is None or o.name == args.org]
        if args.org and not orgs:
            raise AppError(f"{args.email} is not a member of {args.org}")
        issued = await SessionService(UnitOfWork(db), settings).open(
            Account("user", user.id, orgs[0].id if orgs else None, user.email),
            force=args.force,
            via="token.cli",
        )
        return issued.access_token
    raise AppError(f"unknown command {args.command}")


@asynccontextmanager
async def _session_end_announcer(
    settings: Settings,
) -> AsyncIterator[tuple[SessionEndListener, ...]]:
    """Session-end listeners that make the running servers close the ended sessions' sockets
    at once, through the Redis broker they share. Without one (REDIS_URL unset, or Redis away)
    none: each server notices the end at its next look at the session (RECHECK_S)."""
    if not settings.redis_url:
        yield ()
        return
    broker = RedisBroker(settings.redis_url)
    try:
        await broker.start()
    except Exception as err:  # the password change does not wait for Redis
        log.warning("sessions ended, but Redis could not be told: %r", err)
        yield ()
        return
    try:
        yield (functools.partial(announce_sessions_ended, broker),)
    finally:
        await broker.close()


def _checked(password: str) -> str:
    if len(password) < 12:
        raise AppError("the password must have at least 12 characters")
    return password
