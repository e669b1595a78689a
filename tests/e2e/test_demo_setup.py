"""The demo's set-up steps on their own: quick, through the real CLI and a real SQLite file."""

from __future__ import annotations

import sqlite3

from aerobase.demo.run import create_superuser


def test_the_demo_creates_its_superuser_whatever_its_generated_password_begins_with(tmp_path):
    """secrets.token_urlsafe may begin a password with "-": given as `--password -x...` the CLI
    read it as an option and the demo stopped (1 start in 64)."""
    db = tmp_path / "aerobase.db"
    env = {"DATABASE_URL": f"sqlite+aiosqlite:///{db}"}
    create_superuser("root@demo.aerobase", "-Xr5Qd0-generated_k", env)
    with sqlite3.connect(db) as c:
        rows = c.execute("SELECT email FROM users").fetchall()
    assert rows == [("root@demo.aerobase",)]
