"""The core of an NTRIP v2 caster: a sourcetable and one live RTCM3 mountpoint per landing base.

Mount with `app.include_router(ntrip_router(source, authenticate))`. `source` lists the
mountpoints and opens live frame subscriptions; `authenticate(username, password, address)`
returns the caller's organisation id or None. A mountpoint whose `organisation_id` is set is visible and
streamable only to that organisation (others get 404, as for any resource of another
organisation); one whose `organisation_id` is None is public to any authenticated user.
"""

from __future__ import annotations

import asyncio
import base64
import binascii
import inspect
import logging
from collections import defaultdict
from collections.abc import AsyncIterator, Awaitable, Callable, Iterable, Sequence
from dataclasses import dataclass
from typing import Any, Protocol

from fastapi import APIRouter, Request, Response
from fastapi.responses import JSONResponse, StreamingResponse

from protocol.rtcm import frame_ok
from server.kit.metrics import NTRIP_CLIENTS
from server.stations.recheck import RECHECK_S, Recheck, Still, rechecked, still_allowed

log = logging.getLogger(__name__)

NTRIP_VERSION = "Ntrip/2.0"
SERVER_NAME = "NTRIP Aerobase/0.1"
COMMON_HEADERS = {
    "Ntrip-Version": NTRIP_VERSION,
    "Server": SERVER_NAME,
    "Cache-Control": "no-store, no-cache, max-age=0",
    "Pragma": "no-cache",
}

# (username, password, the caller's address or None) -> organisation id, or None: refused
Authenticate = Callable[[str, str, str | None], Awaitable[Any | None]]
# what the HTTP route says to a version 1 client, which cannot read an HTTP status line's stream
V1_HERE = (
    "this route requires the header Ntrip-Version: Ntrip/2.0; NTRIP 1 clients (RTKLIB's str2str, "
    "many receivers) connect to the caster's own port (AEROBASE_NTRIP_PORT, 2101 by convention)"
)


@dataclass(frozen=True)
class Mountpoint:
    """One sourcetable STR entry (NTRIP v2 field order) plus the organisation that owns it."""

    name: str
    identifier: str = ""
    format: str = "RTCM 3.3"
    format_details: str = ""
    carrier: int = 2  # 0 none, 1 L1, 2 L1+L2
    nav_system: str = "GPS+GAL"
    network: str = "Aerobase"
    country: str = ""
    latitude: float = 0.0
    longitude: float = 0.0
    nmea: bool = False
    solution: int = 0  # 0 single base, 1 network
    generator: str = "Aerobase"
    compression: str = "none"
    authentication: str = "B"  # N none, B basic, D digest
    fee: bool = False
    bitrate: int = 0
    misc: str = ""
    organisation_id: Any | None = None
    asset_id: Any | None = None  # the landing base whose corrections this is (not published)

    def str_line(self) -> str:
        """This mountpoint as a sourcetable STR line (without the CRLF)."""
        fields = [
            "STR",
            self.name,
            self.identifier,
            self.format,
            self.format_details,
            str(self.carrier),
            self.nav_system,
            self.network,
            self.country,
            f"{self.latitude:.2f}",
            f"{self.longitude:.2f}",
            "1" if self.nmea else "0",
            str(self.solution),
            self.generator,
            self.compression,
            self.authentication,
            "Y" if self.fee else "N",
            str(self.bitrate),
            self.misc,
        ]
        return ";".join(_clean(f) for f in fields)


class CorrectionsSource(Protocol):
    """What the caster needs from the rest of the server."""

    def mountpoints(self) -> Sequence[Mountpoint] | Awaitable[Sequence[Mountpoint]]:
        """Every mountpoint (the caster filters by organisation)."""
        ...

    def subscribe(self, mountpoint: Mountpoint) -> AsyncIterator[bytes]:
        """Live RTCM3 frames of `mountpoint` from now on; closing the iterator unsubscribes."""
        ...


def mountpoint_name(name: str) -> str:
    """A safe mountpoint name for a base name: letters, digits, '-' and '_' kept, the rest '_'."""
    cleaned = "".join(
        c if c.isascii() and (c.isalnum() or c in "-_") else "_" for c in name.strip()
    )
    return cleaned or "_"


def _clean(value: str) -> str:
    return value.replace(";", ",").replace("\r", " ").replace("\n", " ")


def format_details(rates_s: dict[int, float]) -> str:
    """STR format-details: message types with their intervals in seconds, e.g. `1005(1),1077(1)`."""
    return ",".join(f"{t}({rates_s[t]:g})" for t in sorted(rates_s))


def sourcetable(mountpoints: Iterable[Mountpoint]) -> str:
    """An NTRIP v2 sourcetable body: STR lines, then ENDSOURCETABLE, CRLF-terminated."""
    lines = [m.str_line() for m in mountpoints]
    lines.append("ENDSOURCETABLE")
    return "".join(line + "\r\n" for line in lines)


def parse_basic_auth(header: str | None) -> tuple[str, str] | None:
    """(username, password) from an `Authorization: Basic ...` header, or None when absent/invalid."""
    if not header:
        return None
    scheme, _, token = header.strip().partition(" ")
    if scheme.lower() != "basic" or not token:
        return None
    try:
        decoded = base64.b64decode(token.strip(), validate=True).decode("utf-8")
    except (binascii.Error, UnicodeDecodeError, ValueError):  # ValueError: non-ASCII bytes
        return None
    user, sep, password = decoded.partition(":")
    if not sep:
        return None
    return user, password


def visible_to(mountpoints: Iterable[Mountpoint], organisation_id: Any | None) -> list[Mountpoint]:
    """The mountpoints an organisation may see (its own and public ones); None sees public only."""
    return [
        m
        for m in mountpoints
        if m.organisation_id is None
        or (organisation_id is not None and m.organisation_id == organisation_id)
    ]


def is_version_2(header: str | None) -> bool:
    """Whether an `Ntrip-Version` header asks for NTRIP 2.0 (absent: a version 1 client)."""
    return (header or "").strip().lower() == NTRIP_VERSION.lower()


async def all_mountpoints(source: CorrectionsSource) -> list[Mountpoint]:
    """Every mountpoint of `source`, whether it lists them at once or by awaiting."""
    result = source.mountpoints()
    if inspect.isawaitable(result):
        result = await result
    return list(result)


async def identify(
    authenticate: Authenticate, header: str | None, address: str | None = None
) -> tuple[bool, Any | None]:
    """(credentials acceptable, organisation id) for an `Authorization` header; no header at all
    is acceptable, as anonymous (None: public mountpoints only)."""
    if header is None:
        return True, None
    creds = parse_basic_auth(header)
    if creds is None:
        return False, None
    org = await authenticate(*creds, address)
    return org is not None, org


async def find_mountpoint(
    source: CorrectionsSource, organisation_id: Any | None, name: str
) -> Mountpoint | None:
    """The mountpoint `name` if that organisation may see it."""
    visible = visible_to(await all_mountpoints(source), organisation_id)
    return next((m for m in visible if m.name == name), None)


def _error(status: int, code: str, message: str, headers: dict[str, str] | None = None) -> Response:
    return JSONResponse(
        {"error": {"code": code, "message": message, "details": None}},
        status_code=status,
        headers={**COMMON_HEADERS, **(headers or {})},
    )


def ntrip_router(
    source: CorrectionsSource,
    authenticate: Authenticate,
    *,
    prefix: str = "/ntrip",
    realm: str = "Aerobase NTRIP caster",
    recheck: Recheck | None = None,
    recheck_s: float = RECHECK_S,
) -> APIRouter:
    """An APIRouter serving `GET {prefix}/` (sourcetable) and `GET {prefix}/{mountpoint}` (stream);
    a stream ends when `recheck` says its account may no longer take it (`rechecked`)."""
    router = APIRouter(prefix=prefix, tags=["ntrip"])
    challenge = {"WWW-Authenticate": f'Basic realm="{realm}"'}

    async def table(request: Request) -> Response:
        ok, org = await identify(
            authenticate, request.headers.get("authorization"), _address(request)
        )
        if not ok:
            return _error(401, "unauthorized", "bad NTRIP credentials", challenge)
        body = sourcetable(visible_to(await all_mountpoints(source), org))
        return Response(
            body, media_type="gnss/sourcetable", headers={**COMMON_HEADERS, "Connection": "close"}
        )

    router.add_api_route(
        "/", table, methods=["GET"], include_in_schema=True, summary="NTRIP sourcetable"
    )
    if prefix:
        router.add_api_route("", table, methods=["GET"], include_in_schema=False)

    @router.get("/{mountpoint}", summary="NTRIP v2 corrections stream (gnss/data, chunked)")
    async def stream(mountpoint: str, request: Request) -> Response:
        """Stream a mountpoint's live RTCM3 frames to an authenticated NTRIP v2 client."""
        if not is_version_2(request.headers.get("ntrip-version")):
            return _error(400, "ntrip_version", V1_HERE)
        ok, org = await identify(
            authenticate, request.headers.get("authorization"), _address(request)
        )
        if not ok or org is None:
            return _error(401, "unauthorized", "NTRIP credentials required", challenge)
        found = await find_mountpoint(source, org, mountpoint)
        if found is None:
            return _error(404, "not_found", f"no mountpoint {mountpoint!r}")
        log.info(
            "ntrip client %s on %s", request.client.host if request.client else "?", found.name
        )
        creds = parse_basic_auth(request.headers.get("authorization"))
        still = still_allowed(recheck, creds, org)
        return StreamingResponse(
            _frames(source, found, still, recheck_s),
            media_type="gnss/data",
            # identity keeps a compressing middleware from buffering the live stream
            headers={**COMMON_HEADERS, "Connection": "close", "Content-Encoding": "identity"},
        )

    return router


def _address(request: Request) -> str | None:
    """The caller's address (uvicorn takes it from the proxy's X-Forwarded-For it trusts)."""
    return request.client.host if request.client else None


async def _frames(
    source: CorrectionsSource,
    mountpoint: Mountpoint,
    still: Still | None,
    recheck_s: float,
) -> AsyncIterator[bytes]:
    subscription = rechecked(source.subscribe(mountpoint), still, recheck_s)
    NTRIP_CLIENTS.labels("2").inc()
    try:
        async for frame in subscription:
            yield frame
    finally:
        NTRIP_CLIENTS.labels("2").dec()
        await subscription.aclose()
        log.info("ntrip client left %s", mountpoint.name)


class PubSub(Protocol):
    """The part of the server's realtime broker the caster uses (in-process or Redis)."""

    def subscribe(self, channel: str, handler: Callable[[dict[str, Any]], None]) -> None:
        """Call `handler` for each message on `channel`."""
        ...

    def unsubscribe(self, channel: str, handler: Callable[[dict[str, Any]], None]) -> None:
        """Stop calling `handler`."""
        ...


async def broker_frames(
    broker: PubSub, channel: str, queue_size: int = 256
) -> AsyncIterator[bytes]:
    """Frames published on `channel` as `{"data": <base64 frame>}`; bad ones are logged and skipped."""
    queue: asyncio.Queue[bytes] = asyncio.Queue(queue_size)

    def handler(message: dict[str, Any]) -> None:
        try:
            frame = base64.b64decode(message["data"], validate=True)
        except (KeyError, TypeError, binascii.Error, ValueError):
            log.warning("ntrip: malformed corrections message on %s", channel)
            return
        if not frame_ok(frame):
            log.warning("ntrip: dropped a frame with a bad CRC on %s", channel)
            return
        if queue.full():
            queue.get_nowait()  # a slow client loses the oldest frame, never the newest
        queue.put_nowait(frame)

    broker.subscribe(channel, handler)
    try:
        while True:
            yield await queue.get()
    finally:
        broker.unsubscribe(channel, handler)


class LiveCorrections:
    """An in-process fan-out of each mountpoint's live frames (a single-server `subscribe`)."""

    def __init__(self, queue_size: int = 256) -> None:
        self._queue_size = queue_size
        self._subscribers: dict[str, set[asyncio.Queue[bytes]]] = defaultdict(set)
        self.dropped = 0

    def publish(self, mountpoint: str, frame: bytes) -> None:
        """Hand one frame to every subscriber of `mountpoint` (a full queue loses its oldest)."""
        for queue in self._subscribers.get(mountpoint, ()):
            if queue.full():
                queue.get_nowait()
                self.dropped += 1
            queue.put_nowait(frame)

    def subscribers(self, mountpoint: str) -> int:
        """How many live subscriptions `mountpoint` has."""
        return len(self._subscribers.get(mountpoint, ()))

    async def subscribe(self, mountpoint: str) -> AsyncIterator[bytes]:
        """Frames published to `mountpoint` from now on."""
        queue: asyncio.Queue[bytes] = asyncio.Queue(self._queue_size)
        self._subscribers[mountpoint].add(queue)
        try:
            while True:
                yield await queue.get()
        finally:
            subs = self._subscribers.get(mountpoint)
            if subs is not None:
                subs.discard(queue)
                if not subs:
                    del self._subscribers[mountpoint]
