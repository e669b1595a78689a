"""Server replicas as separate `aerobase server` processes, and nginx in front of them.

Used by the scale-out tests and the native deployment topology (the proxy runs the very server
block docker-compose.yml mounts: deploy/nginx/aerobase.conf).
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import IO

import httpx
import pytest

from aerobase.ports import free_port
from tests.conftest import IN_CI, need_service
from tests.polling import wait_for

REDIS_URL = os.environ.get("REDIS_TEST_URL", "redis://127.0.0.1:6379/0")
ROOT = Path(__file__).resolve().parent.parent
NGINX_SERVER_BLOCK = ROOT / "deploy" / "nginx" / "aerobase.conf"
NGINX_NTRIP_BLOCK = ROOT / "deploy" / "nginx" / "ntrip.conf"  # a stream context file
DEBIAN_STREAM_MODULE = Path("/usr/lib/nginx/modules/ngx_stream_module.so")


def _healthy(url: str) -> bool:
    try:
        return httpx.get(f"{url}/api/health", timeout=1).status_code == 200
    except httpx.HTTPError:
        return False


def start_server(
    database_url: str, port: int, log: IO[bytes], settings: dict[str, str] | None = None
) -> subprocess.Popen[bytes]:
    """One replica on `port` (fast password hashing, Redis broker, `settings` as environment
    variables on top); returns once it is healthy."""
    env = {
        **os.environ,
        "DATABASE_URL": database_url,
        "REDIS_URL": REDIS_URL,
        "AEROBASE_PORT": str(port),
        "AEROBASE_ARGON2_MEMORY_KIB": "8192",
        "AEROBASE_ARGON2_TIME_COST": "1",
        "AEROBASE_ARGON2_PARALLELISM": "1",
        "AEROBASE_CONFIG_SCRYPT_LOG_N": "12",
        "AEROBASE_LOGIN_MAX_FAILURES_ADDRESS": "10000",
        "AEROBASE_LOG_FORMAT": "json",
        **(settings or {}),
    }
    proc = subprocess.Popen(
        [sys.executable, "-m", "aerobase.cli", "server", "--port", str(port)],
        env=env,
        stdout=log,
        stderr=subprocess.STDOUT,
    )

    def up() -> bool:
        if proc.poll() is not None:
            raise AssertionError(f"server on {port} exited with {proc.returncode}")
        return _healthy(f"http://127.0.0.1:{port}")

    try:
        wait_for(up, 60, f"the server on port {port}", interval=0.1)
    except AssertionError:
        proc.kill()
        raise
    return proc


def stop(procs: list[subprocess.Popen[bytes]]) -> None:
    """Terminate, then kill what has not exited within 15 s."""
    for p in procs:
        if p.poll() is None:
            p.terminate()
    for p in procs:
        try:
            p.wait(15)
        except subprocess.TimeoutExpired:
            p.kill()
            p.wait()


@contextmanager
def replicas(
    database_url: str,
    folder: Path,
    count: int = 2,
    settings: dict[str, str] | list[dict[str, str]] | None = None,
) -> Iterator[list[tuple[int, subprocess.Popen[bytes]]]]:
    """`count` replicas on one database and Redis: (port, process) each; stopped on exit.
    `settings` for all of them, or a list: each replica its own."""
    need_service("Redis", "127.0.0.1", 6379)
    started: list[tuple[int, subprocess.Popen[bytes]]] = []
    each = settings if isinstance(settings, list) else [settings or {}] * count
    with open(folder / "servers.log", "wb") as log:
        try:
            for i in range(count):
                port = free_port()
                started.append((port, start_server(database_url, port, log, each[i])))
            yield started
        finally:
            stop([p for _, p in started])


def _servers(ports: list[int]) -> str:
    return "".join(f"server 127.0.0.1:{p} max_fails=1 fail_timeout=5s;\n" for p in ports)


def nginx_binary() -> str:
    """Debian's nginx (installed by .ci/run); a missing binary fails in CI and skips elsewhere."""
    found = shutil.which("nginx") or (
        "/usr/sbin/nginx" if Path("/usr/sbin/nginx").exists() else None
    )
    if found is None:
        if IN_CI:
            pytest.fail("nginx is not installed (CI=true: .ci/run installs it)")
        pytest.skip("nginx is not installed (apt-get install nginx); in CI this fails instead")
    return found


@contextmanager
def proxy(
    upstream_ports: list[int], folder: Path, ntrip: tuple[int, list[int]] | None = None
) -> Iterator[str]:
    """nginx on a free port running deploy/nginx/aerobase.conf in front of `upstream_ports`;
    with `ntrip` (a port to listen on, the replicas' caster ports) also deploy/nginx/ntrip.conf;
    yields its base URL."""
    binary = nginx_binary()
    prefix = folder / "nginx"
    (prefix / "aerobase").mkdir(parents=True)
    (prefix / "tmp").mkdir()
    (prefix / "aerobase" / "aerobase.conf").symlink_to(NGINX_SERVER_BLOCK)
    (prefix / "aerobase" / "upstream.conf").write_text(_servers(upstream_ports))
    port = free_port()
    (prefix / "aerobase" / "listen.conf").write_text(f"listen 127.0.0.1:{port};\n")
    user = "user root;\n" if os.geteuid() == 0 else ""
    temp = "".join(
        f"    {kind}_temp_path tmp/{kind};\n"
        for kind in ("client_body", "proxy", "fastcgi", "uwsgi", "scgi")
    )
    stream = ""
    if ntrip is not None:
        (prefix / "ntrip.conf").symlink_to(NGINX_NTRIP_BLOCK)
        (prefix / "aerobase" / "ntrip-upstream.conf").write_text(_servers(ntrip[1]))
        (prefix / "aerobase" / "ntrip-listen.conf").write_text(f"listen 127.0.0.1:{ntrip[0]};\n")
        stream = "stream {\n    include ntrip.conf;\n}\n"
        if DEBIAN_STREAM_MODULE.exists():  # Debian builds it as a module (libnginx-mod-stream)
            user += f"load_module {DEBIAN_STREAM_MODULE};\n"
    (prefix / "nginx.conf").write_text(
        f"{user}daemon off;\npid nginx.pid;\nerror_log error.log info;\n"
        "events { worker_connections 1024; }\n"
        f"http {{\n    access_log access.log;\n{temp}    include aerobase/aerobase.conf;\n}}\n"
        + stream
    )
    with open(prefix / "nginx.out", "wb") as out:
        proc = subprocess.Popen(
            [binary, "-p", str(prefix), "-c", str(prefix / "nginx.conf")],
            stdout=out,
            stderr=subprocess.STDOUT,
        )
        try:
            url = f"http://127.0.0.1:{port}"

            def up() -> bool:
                if proc.poll() is not None:
                    log = (prefix / "nginx.out").read_text() + (prefix / "error.log").read_text()
                    raise AssertionError(f"nginx exited with {proc.returncode}: {log}")
                return _healthy(url)

            wait_for(up, 20, "nginx in front of the replicas", interval=0.05)
            yield url
        finally:
            stop([proc])
