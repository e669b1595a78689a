"""The `aerobase admin` and `aerobase asset decrypt` commands, run as real processes."""

from __future__ import annotations

import base64
import os
import subprocess
import sys
import tempfile
import uuid

import pytest

from aerobase.ports import free_port
from tests.conftest import Tenant, auth


def _run(
    args: list[str], env: dict[str, str], stdin: str | None = None
) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "aerobase.cli", *args],
        env={**os.environ, **env},
        capture_output=True,
        text=True,
        timeout=120,
        input=stdin,
    )


@pytest.mark.slow
def test_admin_bootstrap_and_token(database_url, api):
    env = {
        "DATABASE_URL": database_url,
        "AEROBASE_ARGON2_MEMORY_KIB": "8192",
        "AEROBASE_ARGON2_TIME_COST": "1",
    }
    assert _run(["admin", "migrate"], env).returncode == 0
    org, email = f"cli-org-{uuid.uuid4().hex[:8]}", f"cli-{uuid.uuid4().hex[:8]}@x.test"
    r = _run(["admin", "create-org", org], env)
    assert r.returncode == 0, r.stderr
    org_id = r.stdout.strip()
    r = _run(["admin", "create-org", org], env)
    assert r.returncode == 1 and "already exists" in r.stderr and "Traceback" not in r.stderr
    r = _run(
        ["admin", "create-user", "--org", org, "--email", email, "--role", "operator"],
        {**env, "AEROBASE_PASSWORD": "cli-password-123"},
    )
    assert r.returncode == 0, r.stderr
    r = _run(
        [
            "admin",
            "create-user",
            "--org",
            org,
            "--email",
            f"short-{uuid.uuid4().hex[:8]}@x.test",
            "--role",
            "viewer",
            "--password",
            "short",
        ],
        env,
    )
    assert r.returncode == 1 and "12 characters" in r.stderr
    r = _run(
        [
            "admin",
            "create-superuser",
            "--email",
            f"root-{uuid.uuid4().hex[:8]}@x.test",
            "--password",
            "root-password-123",
        ],
        env,
    )
    assert r.returncode == 0, r.stderr
    token = _run(["admin", "token", "--email", email], env).stdout.strip()
    me = api.get("/api/v1/auth/me", headers=auth(token)).json()
    assert me["organization_id"] == org_id and me["role"] == "operator"
    # the one-session rule holds for scripts too
    r = _run(["admin", "token", "--email", email], env)
    assert r.returncode == 1 and "live session" in r.stderr
    token = _run(["admin", "token", "--email", email, "--force"], env).stdout.strip()
    # a new password from the shell: the user's sessions end, the new password logs in
    r = _run(["admin", "set-password", "--email", email, "--password", "cli-password-456"], env)
    assert r.returncode == 0 and "1 session(s) ended" in r.stdout, (r.stdout, r.stderr)
    assert api.get("/api/v1/auth/me", headers=auth(token)).status_code == 401
    body = {"email": email, "password": "cli-password-456"}
    assert api.post("/api/v1/auth/login", json=body).status_code == 200
    # Redis named but away: the password is set all the same, and the CLI says the servers
    # were not told (their sockets close at the next look at the session)
    away = {**env, "REDIS_URL": f"redis://127.0.0.1:{free_port()}/0"}
    r = _run(["admin", "set-password", "--email", email, "--password", "cli-password-789"], away)
    assert r.returncode == 0 and "their sockets close within 30 s" in r.stdout, r.stdout
    assert "Redis could not be told" in r.stderr and "Traceback" not in r.stderr, r.stderr
    body = {"email": email, "password": "cli-password-789"}
    assert api.post("/api/v1/auth/login", json=body).status_code == 200
    r = _run(["admin", "set-password", "--email", "nobody@x.test", "--password", "x" * 12], env)
    assert r.returncode == 1 and "no user" in r.stderr and "Traceback" not in r.stderr


def test_asset_decrypt(tenant: Tenant):
    asset = tenant.create_asset(password="decrypt-password-1")
    with tempfile.TemporaryDirectory() as tmp:
        path = os.path.join(tmp, "asset.enc")
        with open(path, "wb") as f:
            f.write(base64.b64decode(asset["config_file"]))
        r = _run(["asset", "decrypt", path], {"AEROBASE_ASSET_PASSWORD": "decrypt-password-1"})
        assert r.returncode == 0, r.stderr
        assert asset["id"] in r.stdout and '"secret"' in r.stdout
        r = _run(["asset", "decrypt", path], {"AEROBASE_ASSET_PASSWORD": "wrong-password-1"})
        assert r.returncode == 1 and "wrong password" in r.stderr
        assert len(r.stderr.strip().splitlines()) == 1 and "Traceback" not in r.stderr
        pw = os.path.join(tmp, "pw")
        with open(pw, "w") as f:
            f.write("decrypt-password-1\n")
        os.chmod(pw, 0o644)
        r = _run(["asset", "decrypt", path, "--password-file", pw], {"AEROBASE_ASSET_PASSWORD": ""})
        assert r.returncode == 1 and "chmod 600" in r.stderr
        os.chmod(pw, 0o600)
        r = _run(["asset", "decrypt", path, "--password-file", pw], {"AEROBASE_ASSET_PASSWORD": ""})
        assert r.returncode == 0, r.stderr
        data = bytearray(open(path, "rb").read())
        data[40] ^= 0xFF
        open(path, "wb").write(bytes(data))
        r = _run(["asset", "decrypt", path], {"AEROBASE_ASSET_PASSWORD": "decrypt-password-1"})
        assert r.returncode == 1 and "altered" in r.stderr and "Traceback" not in r.stderr


@pytest.mark.slow
def test_precland_eval_route_works_outside_the_checkout(tmp_path):
    """`aerobase sim precland-eval` (DESIGN.md's stable command) reaches bench/precland_eval.py
    from any directory, one scenario, one trial."""
    r = subprocess.run(
        [
            sys.executable,
            "-m",
            "aerobase.cli",
            "sim",
            "precland-eval",
            "--trials",
            "1",
            "--scenario",
            "fused",
            "--json",
        ],
        cwd=tmp_path,
        capture_output=True,
        text=True,
        timeout=170,
    )
    assert r.returncode == 0, r.stderr
    assert '"fused"' in r.stdout.splitlines()[-1]


@pytest.mark.parametrize(
    ("database", "said"),
    [
        ("127.0.0.1:5432/no_such_database_here", 'database "no_such_database_here" does not exist'),
        ("127.0.0.1:1/test", "Connect call failed"),
    ],
)
def test_admin_on_a_database_it_cannot_use_says_so_in_one_line_without_the_password(
    database: str, said: str
):
    """An operator's first `docker compose run ... migrate` against a wrong DATABASE_URL reads one
    line naming the database (password hidden) and what it said, not a traceback."""
    env = {"DATABASE_URL": f"postgresql+asyncpg://postgres:hunter2-secret@{database}"}
    r = _run(["admin", "migrate"], env)
    assert r.returncode == 1
    assert r.stderr.strip().count("\n") == 0 and "Traceback" not in r.stderr, r.stderr
    assert r.stderr.startswith("aerobase admin migrate: the database postgresql+asyncpg://")
    assert said in r.stderr and "hunter2-secret" not in r.stderr and "***" in r.stderr
