"""The demo's set-up steps on their own: quick, through the real CLI, a real server and a real
SQLite file."""

from __future__ import annotations

import socket
import sqlite3
from types import SimpleNamespace

from aerobase.demo.processes import Processes
from aerobase.demo.run import NTRIP_PORT, create_superuser, start_server
from aerobase.ports import free_port
from tests.conftest import reachable


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
