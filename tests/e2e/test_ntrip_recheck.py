"""A rover's stream ends once its account may no longer take it: the user disabled in the
organisation, on either door (the caster's own port, NTRIP 1; the HTTP port's /ntrip/, NTRIP 2),
or its password reset to another, while other users' rovers on the same base keep their
corrections (and a reset to the very same password ends nothing)."""

from __future__ import annotations

import asyncio
import base64
from dataclasses import dataclass, field

import httpx
import pytest

from assetlink.configfile import decrypt_config
from assetlink.link import Link
from server.deps import services_of
from tests.conftest import LiveServer, Tenant, test_settings
from tests.metrics import value
from tests.polling import eventually
from tests.rtk import base_sending

pytestmark = pytest.mark.slow  # a server, a base daemon's link and the simulated receiver


@dataclass
class Rover:
    """What a rover has read so far, and whether the caster ended its stream."""

    received: int = 0
    ended: bool = False
    head: bytes = b""
    task: asyncio.Task[None] | None = field(default=None, repr=False)


def _basic(email: str) -> str:
    return base64.b64encode(f"{email}:{Tenant.PASSWORD}".encode()).decode()


async def _v1(port: int, mountpoint: str, email: str) -> Rover:
    rover = Rover()
    reader, writer = await asyncio.open_connection("127.0.0.1", port)
    writer.write(
        f"GET /{mountpoint} HTTP/1.0\r\nAuthorization: Basic {_basic(email)}\r\n\r\n".encode()
    )

    async def read() -> None:
        try:
            while chunk := await reader.read(65536):
                rover.head = rover.head or chunk[:12]
                rover.received += len(chunk)
            rover.ended = True
        finally:
            writer.close()

    rover.task = asyncio.create_task(read())
    return rover


async def _v2(url: str, mountpoint: str, email: str) -> Rover:
    rover = Rover()
    headers = {"Ntrip-Version": "Ntrip/2.0", "Authorization": f"Basic {_basic(email)}"}

    async def read() -> None:
        async with (
            httpx.AsyncClient(base_url=url, timeout=30) as client,
            client.stream("GET", f"/ntrip/{mountpoint}", headers=headers) as response,
        ):
            rover.head = str(response.status_code).encode()
            async for chunk in response.aiter_bytes():
                rover.received += len(chunk)
            rover.ended = True

    rover.task = asyncio.create_task(read())
    return rover


async def _fed(rovers: list[Rover]) -> None:
    """Each rover gets more corrections, and none was cut off."""
    now = [r.received for r in rovers]
    await eventually(
        lambda: all(r.received > n + 2000 for r, n in zip(rovers, now, strict=True)),
        what="corrections going on",
    )
    assert not any(r.ended for r in rovers), rovers


async def _rechecks(url: str, outcome: str) -> float:
    """The server's count of stream rechecks with `outcome` (its /metrics, over HTTP)."""
    async with httpx.AsyncClient(base_url=url) as client:
        text = (await client.get("/metrics")).text
    return value(text, "aerobase_ntrip_rechecks_total", outcome=outcome)


async def test_a_disabled_users_streams_end_and_the_others_go_on(
    database_url, api, superuser_email, tmp_path
):
    tenant = Tenant(api, superuser_email, "rover-recheck")
    base = tenant.create_asset("landing_base")
    cfg = decrypt_config(base64.b64decode(base["config_file"]), "asset-password-123")
    settings = test_settings(database_url, ntrip_port=0, ntrip_recheck_s=0.3)
    server = LiveServer(settings).start()
    link = Link(server.url, cfg.name, cfg.secret, tmp_path / "base.db", agent="base_station")
    rovers: list[Rover] = []
    try:
        caster = services_of(server.app).ntrip
        assert caster is not None
        await link.start()
        await link.wait_connected(15)
        async with base_sending(link):
            viewer, operator = tenant.emails["viewer"], tenant.emails["operator"]
            rovers = [
                await _v1(caster.port, base["name"], viewer),
                await _v2(server.url, base["name"], viewer),
                await _v1(caster.port, base["name"], operator),
                await _v1(caster.port, base["name"], tenant.emails["admin"]),
            ]
            await eventually(
                lambda: all(r.received > 2000 for r in rovers), what="corrections at every rover"
            )
            assert rovers[0].head.startswith(b"ICY 200 OK") and rovers[1].head == b"200"
            r = api.patch(
                f"/api/v1/users/{tenant.user_ids['viewer']}",
                json={"is_active": False},
                headers=tenant.h(),
            )
            assert r.status_code == 200, r.text
            await eventually(lambda: rovers[0].ended and rovers[1].ended, what="viewer cut off")
            ended = await _rechecks(server.url, "ended")
            await _fed(rovers[2:])
            reset = f"/api/v1/users/{tenant.user_ids['operator']}/password"
            # the same password again: a new hash, one password check, and the streams go on
            # through rechecks made after it (three a stream: each rechecked at the same period)
            allowed = await _rechecks(server.url, "allowed")
            r = api.post(reset, json={"new_password": Tenant.PASSWORD}, headers=tenant.h())
            assert r.status_code == 204, r.text
            after = allowed + 3 * len(rovers[2:])

            async def rechecked_since() -> bool:
                return await _rechecks(server.url, "allowed") >= after

            await eventually(rechecked_since, what="rechecks after it", interval=0.1)
            await _fed(rovers[2:])
            assert await _rechecks(server.url, "ended") == ended  # only the viewer's two
            r = api.post(reset, json={"new_password": "another-password-9"}, headers=tenant.h())
            assert r.status_code == 204, r.text
            await eventually(lambda: rovers[2].ended, what="the operator's rover cut off")
            await _fed(rovers[3:])
    finally:
        for rover in rovers:
            if rover.task is not None:
                rover.task.cancel()
        await asyncio.gather(*(r.task for r in rovers if r.task), return_exceptions=True)
        await link.stop()
        await asyncio.to_thread(server.stop)
