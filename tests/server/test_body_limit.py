"""Oversized request bodies are refused with 413 before they are read (issue 14, item 9).

Raw sockets, so the test controls how much of the body is sent: the server must answer while the
client still holds most of a 64 MiB body, both when `Content-Length` declares it and when it is
streamed in chunks without one.
"""

from __future__ import annotations

import json
import socket
from typing import Any
from urllib.parse import urlsplit

from tests.conftest import Tenant
from tests.metrics import value
from tests.polling import wait_for

MIB = 1024 * 1024
DEFAULT_LIMIT = 1 * MIB  # Settings.max_body_bytes
IMPORT_LIMIT = 5 * MIB  # Settings.max_import_bytes


class Response:
    """Status, headers and JSON body of one HTTP/1.1 response read off a raw socket."""

    def __init__(self, sock: socket.socket) -> None:
        data = b""
        while b"\r\n\r\n" not in data:
            chunk = sock.recv(65536)
            assert chunk, f"connection closed before a response: {data!r}"
            data += chunk
        head, _, rest = data.partition(b"\r\n\r\n")
        lines = head.decode("latin-1").split("\r\n")
        self.status = int(lines[0].split()[1])
        self.headers = {k.lower(): v.strip() for k, _, v in (ln.partition(":") for ln in lines[1:])}
        length = int(self.headers.get("content-length", "0"))
        while len(rest) < length:
            chunk = sock.recv(65536)
            assert chunk, "connection closed inside the response body"
            rest += chunk
        self.body: Any = json.loads(rest[:length]) if length else None


def _connect(url: str) -> socket.socket:
    u = urlsplit(url)
    sock = socket.create_connection((u.hostname, u.port), timeout=10)
    return sock


def _head(path: str, headers: dict[str, str]) -> bytes:
    lines = [f"POST {path} HTTP/1.1", "Host: test", *(f"{k}: {v}" for k, v in headers.items())]
    return ("\r\n".join(lines) + "\r\n\r\n").encode()


def test_a_declared_64_mib_body_is_refused_before_a_byte_of_it_is_read(live_server):
    """Before: the server waited for (and read) all 64 MiB of an unauthenticated login, then 422."""
    with _connect(live_server.url) as sock:
        sock.sendall(
            _head(
                "/api/v1/auth/login",
                {"Content-Type": "application/json", "Content-Length": str(64 * MIB)},
            )
        )
        r = Response(sock)  # no body byte sent yet
        assert r.status == 413, r.body
        assert r.body["error"]["code"] == "too_large"
        assert str(DEFAULT_LIMIT) in r.body["error"]["message"]
        assert r.headers["connection"] == "close"
        assert sock.recv(1) == b""  # the server closed instead of draining the rest


def _chunk(data: bytes) -> bytes:
    return b"%x\r\n%s\r\n" % (len(data), data)


def test_a_streamed_body_is_counted_and_refused_at_the_chunk_over_the_limit(live_server):
    """Chunked, no Content-Length: refused once 1 MiB + 1 byte arrived; 63 MiB were never sent."""
    with _connect(live_server.url) as sock:
        sock.sendall(
            _head(
                "/api/v1/auth/login",
                {"Content-Type": "application/json", "Transfer-Encoding": "chunked"},
            )
        )
        piece = b" " * 65536
        sent = 0
        for _ in range(DEFAULT_LIMIT // len(piece)):
            sock.sendall(_chunk(piece))
            sent += len(piece)
        sock.sendall(_chunk(b"{"))  # the byte over the limit; the client now waits
        sent += 1
        r = Response(sock)
        assert r.status == 413, r.body
        assert r.body["error"]["code"] == "too_large"
        assert r.headers["connection"] == "close"
        assert sent < 64 * MIB // 60


def test_mission_import_has_its_own_larger_limit(live_server, tenant: Tenant):
    """A 2 MiB .plan (over the default limit) is read; 6 MiB declared is refused up front."""
    plan = json.dumps(
        {
            "fileType": "Plan",
            "mission": {
                "plannedHomePosition": [47.397742, 8.545594, 488],
                "items": [
                    {
                        "type": "SimpleItem",
                        "command": 22,
                        "frame": 3,
                        "params": [0, 0, 0, None, 47.397742, 8.545594, 20],
                    }
                ],
            },
        }
    ).encode()
    body = plan + b" " * (2 * MIB)
    headers = {**tenant.h("operator"), "Content-Type": "application/json"}
    with _connect(live_server.url) as sock:
        sock.sendall(
            _head("/api/v1/missions/import", {**headers, "Content-Length": str(len(body))})
        )
        sock.sendall(body)
        r = Response(sock)
        assert r.status == 201, r.body
    with _connect(live_server.url) as sock:
        sock.sendall(_head("/api/v1/missions/import", {**headers, "Content-Length": str(6 * MIB)}))
        r = Response(sock)
        assert r.status == 413, r.body
        assert str(IMPORT_LIMIT) in r.body["error"]["message"]


def test_a_body_under_the_limit_is_read_as_before(api):
    """The limit changes nothing below it: a junk login of 512 KiB is still a 422."""
    r = api.post(
        "/api/v1/auth/login",
        content=b'{"email": "' + b"a" * (512 * 1024) + b'", "password": "x"}',
        headers={"Content-Type": "application/json"},
    )
    assert r.status_code == 422, r.text


def test_a_client_hanging_up_mid_body_is_no_server_error(live_server, tenant: Tenant, api):
    """A mission import (and the WHEP offer: both read their bodies themselves) whose client
    closes the connection 10 bytes into a declared 1,000: before, an unhandled-error traceback
    and a 500 in the metrics; now 499, as nginx counts a client that hung up."""
    route = "/api/v1/missions/import"
    headers = {**tenant.h("operator"), "Content-Type": "application/json"}

    def counted(status: str) -> float:
        text = api.get("/metrics").text
        return value(text, "aerobase_http_request_duration_seconds_count", method="POST",
                     route=route, status=status)  # fmt: skip

    before = counted("499")
    with _connect(live_server.url) as sock:
        sock.sendall(_head(route, {**headers, "Content-Length": "1000"}) + b'{"fileType')
    wait_for(lambda: counted("499") == before + 1, 10, what="the hang-up counted as 499")
    assert counted("500") == 0
