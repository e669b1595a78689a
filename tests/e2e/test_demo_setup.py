"""The demo's set-up steps on their own: quick, through the real CLI, a real server and a real
SQLite file."""

from __future__ import annotations

import asyncio
import socket
import sqlite3
from types import SimpleNamespace

import httpx

from aerobase.demo.fleet import OPS_EMAIL, ROOT_EMAIL, register
from aerobase.demo.processes import Processes
from aerobase.demo.run import NTRIP_PORT, create_superuser, start_server
from aerobase.ports import free_port
from server import migrate
from tests.conftest import SUPERUSER_PASSWORD, LiveServer, reachable, test_settings
from tests.conftest import create_superuser as create_superuser_in


def test_the_demo_creates_its_superuser_whatever_its_generated_password_begins_with(tmp_path):
    """secrets.token_urlsafe may begin a password with "-": given as `--password -x...` the CLI
    read it as an option and the demo stopped (1 start in 64)."""
    db = tmp_path / "aerobase.db"
    env = {"DATABASE_URL": f"sqlite+aiosqlite:///{db}"}
    create_superuser("root@demo.aerobase", "-Xr5Qd0-generated_k", env)
    with sqlite3.connect(db) as c:
        rows = c.execute("SELECT email FROM users").fetchall()
    assert rows == [("root@demo.aerobase",)]


async def test_a_caster_port_taken_after_the_demo_looked_moves_the_caster_not_the_demo(
    tmp_path, capsys
):
    """Two demos starting side by side both found 2101 free, and the second server to bind it
    exited ("address already in use"): the demo failed at its start (seen in a full test run)."""
    holder: socket.socket | None = socket.socket()
    try:
        holder.bind(("0.0.0.0", NTRIP_PORT))
        holder.listen()
    except OSError:  # another program has it already: taken all the same
        holder.close()
        holder = None
    port = free_port()
    env = {
        "DATABASE_URL": f"sqlite+aiosqlite:///{tmp_path / 'aerobase.db'}",
        "AEROBASE_PUBLIC_URL": f"http://127.0.0.1:{port}",
        "AEROBASE_NTRIP_PORT": str(NTRIP_PORT),  # as prepare() chose it, 2101 then free
    }
    procs = Processes(tmp_path)
    try:
        await start_server(SimpleNamespace(port=port), procs, env, f"http://127.0.0.1:{port}")
        caster = int(env["AEROBASE_NTRIP_PORT"])
        assert caster != NTRIP_PORT
        assert reachable("127.0.0.1", caster)  # the caster listens where the demo now says
        log = (tmp_path / "server.log").read_text()
        assert f", {NTRIP_PORT}): address already in use" in log  # the first start's exit
        assert f"port {NTRIP_PORT} was taken meanwhile" in capsys.readouterr().out
    finally:
        procs.stop()
        if holder is not None:
            holder.close()


async def test_the_printed_operator_login_signs_in_without_a_takeover(tmp_path):
    """Issue 48 finding 11: the demo held its session on the operator account it prints, so a
    newcomer's first sign-in met "this account already has a live session", and taking it over
    killed the token in the printed video link. The demo now works as a user of its own."""
    url = f"sqlite+aiosqlite:///{tmp_path / 'aerobase.db'}"
    await asyncio.to_thread(migrate.upgrade, url)
    await create_superuser_in(url, ROOT_EMAIL)
    server = LiveServer(test_settings(url, ntrip_port=0)).start()
    passwords = {"root": SUPERUSER_PASSWORD, "ops": "ops-password-12", "demo": "demo-password-1"}
    passwords["asset"] = "asset-password-1"
    try:
        async with httpx.AsyncClient(base_url=server.url, timeout=30) as c:
            fleet = await register(c, passwords)
            # the newcomer signs in with the printed login, as the console does: no force
            r = await c.post(
                "/api/v1/auth/login", json={"email": OPS_EMAIL, "password": passwords["ops"]}
            )
            assert r.status_code == 200, r.text
            # and the demo's session (the one in the printed video link) goes on
            me = await c.get("/api/v1/auth/me", headers={"Authorization": f"Bearer {fleet.token}"})
            assert me.status_code == 200 and me.json()["email"] != OPS_EMAIL, me.text
    finally:
        server.stop()
