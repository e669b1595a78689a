"""The NTRIP caster on a TCP port of its own (2101 by convention), for version 1 and 2 clients.

NTRIP 1 is not HTTP: a caster answers a stream request with the status line `ICY 200 OK` and the
raw RTCM3 bytes after it, and a sourcetable with `SOURCETABLE 200 OK`. RTKLIB's str2str, BKG's
NtripClient and the built-in clients of many receivers speak only that and give up on an
`HTTP/1.1 200` (str2str reads nothing from one), so an HTTP server cannot serve them. This
listener speaks both: a request without `Ntrip-Version: Ntrip/2.0` is answered as NTRIP 1, one
with it as NTRIP 2 (HTTP/1.1, chunked `gnss/data`), as the `/ntrip/` routes of the HTTP port do.

The mountpoints, their visibility to an organisation, the credentials and the live frames are
the HTTP caster's (ntrip.py); mountpoints are at the root (`/base-porto-1`) and, as on the HTTP
port, under `/ntrip/`. As version 1 casters do, a request for a mountpoint the caller does not see
is answered with the sourcetable (NTRIP 2: 404). Whatever the client sends once it streams (a
rover's GGA sentences) is read and dropped; its leaving ends the stream.
"""

from __future__ import annotations

import asyncio
import contextlib
import ipaddress
import json
import logging
from collections.abc import AsyncGenerator, Iterable
from dataclasses import dataclass
from email.utils import formatdate
from typing import Any

from server.kit.metrics import NTRIP_CLIENTS
from server.stations.ntrip import (
    SERVER_NAME,
    Authenticate,
    CorrectionsSource,
    Mountpoint,
    all_mountpoints,
    identify,
    is_version_2,
    parse_basic_auth,
    sourcetable,
    visible_to,
)
from server.stations.recheck import RECHECK_S, Recheck, Still, rechecked, still_allowed

log = logging.getLogger(__name__)
HEAD_LIMIT = 8192  # bytes of request line and headers
HEAD_TIMEOUT_S = 10.0  # a client that has not sent its request by then is closed
SEND_TIMEOUT_S = 30.0  # a client that takes nothing for this long is closed
CLOSE_WAIT_S = 1.0  # after our answer, how long a client may take to close its end
REALM = "Aerobase NTRIP caster"
MAX_CLIENTS = 1000  # connections at once; the next is answered 503 and closed


@dataclass(frozen=True)
class Request:
    """An NTRIP request: method, the mountpoint asked for ('' for the sourcetable), headers."""

    method: str
    mountpoint: str
    headers: dict[str, str]  # lower-case names

    @property
    def version_2(self) -> bool:
        return is_version_2(self.headers.get("ntrip-version"))


class BadRequest(ValueError):
    """The bytes are not an NTRIP request."""


def parse_request(head: bytes) -> Request:
    """The request line and headers (CRLF or LF line ends) of an NTRIP request."""
    lines = head.decode("latin-1").replace("\r\n", "\n").split("\n")
    parts = lines[0].split()
    if len(parts) < 2:
        raise BadRequest("no request line")
    path = parts[1].split("?", 1)[0].lstrip("/")
    if path == "ntrip" or path.startswith("ntrip/"):
        path = path[len("ntrip") :].lstrip("/")
    headers: dict[str, str] = {}
    for line in lines[1:]:
        name, sep, value = line.partition(":")
        if sep:
            headers[name.strip().lower()] = value.strip()
    return Request(parts[0].upper(), path, headers)


def proxied_client(line: bytes) -> str | None:
    """The client's address from a PROXY protocol v1 line (`PROXY TCP4 <client> <proxy> <client
    port> <proxy port>`); None for `PROXY UNKNOWN` (the proxy's own check); BadRequest for
    anything else."""
    parts = line.decode("latin-1").split(" ")
    if parts[:2] == ["PROXY", "UNKNOWN"]:
        return None
    if len(parts) != 6 or parts[0] != "PROXY" or parts[1] not in ("TCP4", "TCP6"):
        raise BadRequest("no PROXY protocol line")
    try:
        return str(ipaddress.ip_address(parts[2]))
    except ValueError as err:
        raise BadRequest("no client address in the PROXY line") from err


def _head(status: str, version_2: bool, fields: Iterable[tuple[str, str]] = ()) -> bytes:
    common = [("Server", SERVER_NAME), ("Date", formatdate(usegmt=True))]
    if version_2:
        common += [("Ntrip-Version", "Ntrip/2.0"), ("Connection", "close")]
    lines = [status, *(f"{k}: {v}" for k, v in (*common, *fields))]
    return ("\r\n".join(lines) + "\r\n\r\n").encode("latin-1")


def table_response(mountpoints: list[Mountpoint], version_2: bool) -> bytes:
    """The sourcetable: `SOURCETABLE 200 OK` (NTRIP 1) or an HTTP/1.1 `gnss/sourcetable`."""
    body = sourcetable(mountpoints).encode()
    status, kind = (
        ("HTTP/1.1 200 OK", "gnss/sourcetable")
        if version_2
        else ("SOURCETABLE 200 OK", "text/plain")
    )
    return (
        _head(status, version_2, [("Content-Type", kind), ("Content-Length", str(len(body)))])
        + body
    )


def error_response(status: int, reason: str, code: str, message: str, version_2: bool) -> bytes:
    """An error: the HTTP API's JSON error body (NTRIP 2), or a line of text (NTRIP 1)."""
    if version_2:
        body = json.dumps({"error": {"code": code, "message": message, "details": None}}).encode()
        kind = "application/json"
    else:
        body, kind = f"{status} {reason}: {message}\r\n".encode(), "text/plain"
    fields = [("Content-Type", kind), ("Content-Length", str(len(body)))]
    if status == 401:
        fields.append(("WWW-Authenticate", f'Basic realm="{REALM}"'))
    http = "HTTP/1.1" if version_2 else "HTTP/1.0"
    return _head(f"{http} {status} {reason}", version_2, fields) + body


def stream_head(version_2: bool) -> bytes:
    """What precedes a mountpoint's frames: `ICY 200 OK` alone (NTRIP 1: RTKLIB and BKG's client
    take every byte after it as data, and BKG's wants it in a read of its own), or HTTP headers."""
    if not version_2:
        return b"ICY 200 OK\r\n"
    return _head(
        "HTTP/1.1 200 OK",
        True,
        [
            ("Content-Type", "gnss/data"),
            ("Transfer-Encoding", "chunked"),
            ("Cache-Control", "no-store, no-cache, max-age=0"),
        ],
    )


class Caster:
    """Serves NTRIP 1 and 2 clients on a TCP port until `close()`."""

    def __init__(
        self,
        source: CorrectionsSource,
        authenticate: Authenticate,
        max_clients: int = MAX_CLIENTS,
        proxy_protocol: bool = False,
        recheck: Recheck | None = None,
        recheck_s: float = RECHECK_S,
    ) -> None:
        """`proxy_protocol`: every connection comes from a proxy and starts with a PROXY
        protocol v1 line (nginx's `proxy_protocol on`) naming the client; one without is refused.
        `recheck`: asked every `recheck_s` seconds of a stream whether its account may still take
        it (ntrip.py's `rechecked`)."""
        self.source, self.authenticate, self.max_clients = source, authenticate, max_clients
        self.proxy_protocol = proxy_protocol
        self.recheck, self.recheck_s = recheck, recheck_s
        self._server: asyncio.Server | None = None
        self._clients: dict[asyncio.Task[Any], asyncio.StreamWriter] = {}

    @property
    def port(self) -> int:
        assert self._server is not None, "not started"
        return int(self._server.sockets[0].getsockname()[1])

    @property
    def connected(self) -> int:
        """Clients connected now (streaming or being answered)."""
        return len(self._clients)

    async def start(self, host: str, port: int) -> Caster:
        self._server = await asyncio.start_server(self._connected, host, port)
        log.info("NTRIP caster (versions 1 and 2) on %s:%d", host, self.port)
        return self

    async def close(self) -> None:
        """Stop listening and end every client's connection (its stream ends as if it had left);
        a client that takes nothing (its unsent frames would hold the close) is cut off after
        2 x CLOSE_WAIT_S, so a server's shutdown is not held by a stalled rover."""
        if self._server is not None:
            self._server.close()
        for writer in list(self._clients.values()):
            writer.close()
        if not self._clients:
            return
        _, stalled = await asyncio.wait(list(self._clients), timeout=2 * CLOSE_WAIT_S)
        for task in stalled:
            if (stuck := self._clients.get(task)) is not None:
                stuck.transport.abort()
        if stalled:
            await asyncio.wait(stalled, timeout=CLOSE_WAIT_S)

    async def _connected(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        task = asyncio.current_task()
        assert task is not None
        if len(self._clients) >= self.max_clients:
            message = "too many NTRIP clients; try again later"
            writer.write(error_response(503, "Service Unavailable", "busy", message, False))
            await _close(reader, writer)
            return
        self._clients[task] = writer
        peer = writer.get_extra_info("peername")
        try:
            await self._serve(reader, writer, peer[0] if peer else "?")
        except (ConnectionError, TimeoutError, asyncio.IncompleteReadError):
            pass  # the client left, or took nothing for SEND_TIMEOUT_S
        finally:
            self._clients.pop(task, None)
            await _close(reader, writer)

    async def _serve(
        self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter, peer: str
    ) -> None:
        try:
            async with asyncio.timeout(HEAD_TIMEOUT_S):
                head = await _read_head(reader)
            if self.proxy_protocol:
                proxied, _, head = head.partition(b"\r\n")
                peer = proxied_client(proxied) or peer
            request = parse_request(head)
        except (BadRequest, asyncio.LimitOverrunError, TimeoutError, ValueError):
            writer.write(
                error_response(400, "Bad Request", "bad_request", "not an NTRIP request", False)
            )
            return await _drain(writer)
        v2 = request.version_2
        try:
            answer = await self._answer(request, peer)
        except Exception:  # the database or the broker away: say so, never just hang up
            log.exception("ntrip: could not answer %s", peer)
            message = "the caster cannot check credentials or mountpoints now; try again"
            answer = error_response(503, "Service Unavailable", "unavailable", message, v2)
        if isinstance(answer, bytes):
            writer.write(answer)
            return await _drain(writer)
        mountpoint, still = answer
        log.info("ntrip client %s on %s (NTRIP %d)", peer, mountpoint.name, 2 if v2 else 1)
        writer.write(stream_head(v2))
        await _drain(writer)
        streaming = NTRIP_CLIENTS.labels("2" if v2 else "1")
        streaming.inc()
        try:
            frames = rechecked(self.source.subscribe(mountpoint), still, self.recheck_s)
            await _stream(frames, reader, writer, v2)
        finally:
            streaming.dec()
            log.info("ntrip client %s left %s", peer, mountpoint.name)

    async def _answer(self, request: Request, peer: str) -> bytes | tuple[Mountpoint, Still | None]:
        """What a request gets: an answer to send and close with, or the mountpoint to stream
        with what to ask of it again."""
        v2 = request.version_2
        if request.method != "GET":
            message = "this caster serves GET (clients); it takes no NTRIP server's SOURCE or POST"
            return error_response(405, "Method Not Allowed", "method", message, v2)
        ok, org = await identify(self.authenticate, request.headers.get("authorization"), peer)
        if not ok or (request.mountpoint and org is None):
            message = "NTRIP credentials required"
            return error_response(401, "Unauthorized", "unauthorized", message, v2)
        visible = visible_to(await all_mountpoints(self.source), org)
        if request.mountpoint:
            found = next((m for m in visible if m.name == request.mountpoint), None)
            if found is not None:
                creds = parse_basic_auth(request.headers.get("authorization"))
                return found, still_allowed(self.recheck, creds, org)
            if v2:
                message = f"no mountpoint {request.mountpoint!r}"
                return error_response(404, "Not Found", "not_found", message, v2)
        # the sourcetable, asked for or (NTRIP 1) in place of a mountpoint the caller does not see
        return table_response(visible, v2)


async def _read_head(reader: asyncio.StreamReader) -> bytes:
    """Bytes up to the blank line ending the request (CRLF or LF)."""
    head = b""
    while b"\r\n\r\n" not in head and b"\n\n" not in head:
        chunk = await reader.read(HEAD_LIMIT)
        if not chunk:
            raise BadRequest("closed before the request ended")
        head += chunk
        if len(head) > HEAD_LIMIT:
            raise BadRequest("request head too long")
    return head


async def _close(reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
    """Send what is left, then close: after our end, what the client sent and we did not read
    (a rover's GGA, a request we refused unread) is taken first, for at most CLOSE_WAIT_S; a
    socket closed with unread data resets the connection, and the client may lose our answer."""
    with contextlib.suppress(Exception):
        await _drain(writer)
        if writer.can_write_eof():
            writer.write_eof()
        async with asyncio.timeout(CLOSE_WAIT_S):
            while await reader.read(HEAD_LIMIT):
                pass
    writer.close()
    with contextlib.suppress(Exception):
        await writer.wait_closed()


async def _drain(writer: asyncio.StreamWriter) -> None:
    async with asyncio.timeout(SEND_TIMEOUT_S):
        await writer.drain()


async def _stream(
    frames: AsyncGenerator[bytes, None],
    reader: asyncio.StreamReader,
    writer: asyncio.StreamWriter,
    version_2: bool,
) -> None:
    """`frames` until the client leaves or they end (what the client sends is dropped)."""

    async def until_gone() -> None:
        while await reader.read(4096):
            pass  # GGA sentences and the like: not used

    async def pump() -> None:
        async for frame in frames:
            writer.write(b"%x\r\n%b\r\n" % (len(frame), frame) if version_2 else frame)
            await _drain(writer)

    pumping, gone = asyncio.create_task(pump()), asyncio.create_task(until_gone())
    try:
        await asyncio.wait({pumping, gone}, return_when=asyncio.FIRST_COMPLETED)
        if pumping.done() and (err := pumping.exception()) is not None:
            raise err  # the client took nothing (TimeoutError) or reset: as if it had left
    finally:
        for task in (pumping, gone):
            task.cancel()  # a cancelled pump ends the subscription where it waits
        await asyncio.gather(pumping, gone, return_exceptions=True)
        with contextlib.suppress(Exception):
            await frames.aclose()
