"""The caster's port fuzzed over real sockets: a seeded generator mutates valid NTRIP 1 and 2
requests (bytes dropped, repeated, replaced with control bytes, NUL or non-ASCII; lines cut,
doubled or made huge; methods, paths and versions swapped). Every connection is answered with a
status line the caster documents, or streams; none is dropped without a word; nothing is logged
as an error; and a well-formed rover is served afterwards."""

from __future__ import annotations

import asyncio
import logging
import random

import pytest

from server.stations import caster as caster_module
from tests.server.test_ntrip_caster import Running, basic, ntrip, v1, v2  # noqa: F401

pytestmark = pytest.mark.slow  # about 10 s

SEED = 2101
REQUESTS = 300
ANSWERS = (
    b"ICY 200 OK\r\n",
    b"SOURCETABLE 200 OK\r\n",
    *(f"HTTP/1.{minor} {code} ".encode() for minor in (0, 1) for code in (200, 400, 401, 404, 405)),
)
NOISE = [b"\x00", b"\xff", b"\r", b"\n", b"\r\n", b":", b" ", b"\t", b"\xc3\x28", b"%", b"/"]


def mutate(rng: random.Random, request: bytes) -> bytes:
    """One to four mutations of a valid request."""
    data = bytearray(request)
    for _ in range(rng.randint(1, 4)):
        kind = rng.randrange(8)
        at = rng.randrange(len(data) + 1)
        if kind == 0 and data:
            del data[at : at + rng.randint(1, 8)]
        elif kind == 1:
            data[at:at] = rng.choice(NOISE) * rng.randint(1, 3)
        elif kind == 2:
            data[at:at] = bytes(rng.randrange(256) for _ in range(rng.randint(1, 16)))
        elif kind == 3:
            data[at:at] = b"X-Long: " + b"a" * rng.choice((100, 5000, 9000)) + b"\r\n"
        elif kind == 4:
            data = bytearray(data.replace(b"GET", rng.choice([b"SOURCE", b"POST", b"get", b""])))
        elif kind == 5:
            data = bytearray(data.replace(b"HTTP/1.", rng.choice([b"HTTP/9.", b"RTSP/1.", b""])))
        elif kind == 6:
            data = bytearray(data.replace(b"Ntrip/2.0", rng.choice([b"Ntrip/1.0", b"", b"x"])))
        else:
            data = data[: rng.randrange(len(data) + 1)]  # cut short: the head may never end
    return bytes(data)


async def first_line(port: int, request: bytes) -> bytes:
    """What the caster answers first (a stream's first bytes are enough)."""
    reader, writer = await asyncio.open_connection("127.0.0.1", port)
    try:
        writer.write(request)
        await writer.drain()
        async with asyncio.timeout(10):
            head = b""
            while b"\r\n" not in head:
                chunk = await reader.read(4096)
                if not chunk:
                    break
                head += chunk
        return head
    finally:
        writer.close()


async def test_every_mutated_request_gets_a_documented_answer_and_the_caster_keeps_serving(
    ntrip: Running,  # noqa: F811
    monkeypatch: pytest.MonkeyPatch,
    caplog: pytest.LogCaptureFixture,
):
    monkeypatch.setattr(caster_module, "HEAD_TIMEOUT_S", 0.1)  # heads cut short: answered sooner
    rng = random.Random(SEED)
    seeds = [
        v1("/BASE1").encode(),
        v1("/").encode(),
        v2("/ntrip/BASE1").encode(),
        v1("/NOPE", basic("bob", "hunter2")).encode(),
    ]
    caplog.set_level(logging.WARNING)
    seen: dict[bytes, int] = {}
    for i in range(REQUESTS):
        request = mutate(rng, seeds[i % len(seeds)])
        answer = await first_line(ntrip.caster.port, request)
        status = next((a for a in ANSWERS if answer.startswith(a)), None)
        assert status is not None, (request, answer[:80])
        seen[status] = seen.get(status, 0) + 1
    assert len(seen) >= 5, seen  # the mutations reach several answers, not one
    errors = [r for r in caplog.records if r.levelno >= logging.ERROR]
    assert errors == [], [r.getMessage() for r in errors]
    # still serving: a well-formed rover streams
    assert (await first_line(ntrip.caster.port, v1("/BASE1").encode())) == b"ICY 200 OK\r\n"
