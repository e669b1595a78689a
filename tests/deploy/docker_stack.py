"""docker-compose.yml as running containers on a machine that reaches no image registry.

Debian's docker.io runs the containers (its daemon is started here when none answers). Every image
is built here: a Debian bookworm made by debootstrap from the machine's own package mirror is the
base (`aerobase-test/bookworm`, standing in for `python:3.11-slim-bookworm` and
`debian:bookworm-slim`), and `stand_ins/` builds the four official images the file names
(PostgreSQL, Redis, InfluxDB, nginx) from Debian's packages. `stand_ins/compose.yml` changes only
images; every command, variable, volume, health check and dependency is the file's own.
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from tests.deploy.conftest import program
from tests.polling import wait_for

ROOT = Path(__file__).resolve().parents[2]
BASE = "aerobase-test/bookworm:latest"
STAND_INS = ROOT / "tests" / "deploy" / "stand_ins" / "compose.yml"
CA_BUNDLE = Path("/etc/ssl/certs/ca-certificates.crt")


def docker_answers() -> bool:
    """True when a Docker daemon answers on its socket."""
    try:
        r = subprocess.run(["docker", "info"], capture_output=True, timeout=30)
    except (FileNotFoundError, subprocess.TimeoutExpired):
        return False
    return r.returncode == 0


@contextmanager
def docker_daemon(log: Path) -> Iterator[None]:
    """A Docker daemon for the block: the one that answers, or Debian's dockerd started here (its
    output to `log`) and stopped after."""
    program("docker", "docker.io")
    if docker_answers():
        yield
        return
    dockerd = program("dockerd", "docker.io")
    with log.open("wb") as out:
        proc = subprocess.Popen([dockerd], stdout=out, stderr=subprocess.STDOUT)
        try:

            def up() -> bool:
                assert proc.poll() is None, f"dockerd exited: {log.read_text()[-2000:]}"
                return docker_answers()

            wait_for(up, within=60, what=f"dockerd to answer (log: {log})", interval=0.5)
            yield
        finally:
            proc.terminate()
            try:
                proc.wait(timeout=30)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()


def debian_mirror() -> str | None:
    """The first Debian archive in the machine's apt sources (deb822 or one-line), or None for
    debootstrap's default."""
    sources = Path("/etc/apt/sources.list.d")
    texts = [p.read_text() for p in sorted(sources.glob("*.sources"))] if sources.is_dir() else []
    for text in texts:
        for uri in re.findall(r"^URIs:\s*(\S+)", text, re.MULTILINE):
            if uri.rstrip("/").endswith("/debian"):
                return uri
    legacy = Path("/etc/apt/sources.list")
    if legacy.is_file():
        m = re.search(r"^deb\s+(?:\[[^]]*\]\s+)?(\S+/debian)/?\s", legacy.read_text(), re.MULTILINE)
        if m:
            return m.group(1)
    return None


def base_image() -> str:
    """`aerobase-test/bookworm`: Debian bookworm (minbase) with CPython 3.11 and venv, `python` on
    the PATH as in the official Python image, and this machine's certificate authorities for pip.
    Made once per Docker daemon (about 40 s), then reused."""
    if subprocess.run(["docker", "image", "inspect", BASE], capture_output=True).returncode == 0:
        return BASE
    debootstrap = program("debootstrap", "debootstrap")
    with tempfile.TemporaryDirectory(prefix="aerobase-rootfs-", dir="/var/tmp") as tmp:
        rootfs = Path(tmp) / "rootfs"
        cmd = [debootstrap, "--variant=minbase", "--include=python3,python3-venv,ca-certificates"]
        cmd += ["bookworm", str(rootfs)]
        mirror = debian_mirror()
        run(cmd + ([mirror] if mirror else []), timeout=600)
        (rootfs / "usr/local/bin/python").symlink_to("/usr/bin/python3")
        if CA_BUNDLE.is_file():  # a site's own authority (a proxy's) reaches the builds' pip
            shutil.copyfile(CA_BUNDLE, rootfs / "etc/ssl/certs/ca-certificates.crt")
        (rootfs / "etc/pip.conf").write_text(f"[global]\ncert = {CA_BUNDLE}\n")
        for cache in ("var/cache/apt/archives", "var/lib/apt/lists"):
            for path in (rootfs / cache).glob("*"):
                if path.is_file():
                    path.unlink()
        tar = subprocess.Popen(["tar", "-C", str(rootfs), "-c", "."], stdout=subprocess.PIPE)
        run(["docker", "import", "-", BASE], stdin=tar.stdout, timeout=300)
        assert tar.wait() == 0, "tar of the root file system failed"
    return BASE


def run(
    cmd: list[str],
    *,
    timeout: float,
    env: dict[str, str] | None = None,
    check: bool = True,
    **kw: object,
) -> subprocess.CompletedProcess[str]:
    """Run `cmd`; with `check`, fail with its output's tail when it exits non-zero."""
    r = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout, env=env, **kw)  # type: ignore[call-overload]
    assert not check or r.returncode == 0, (
        f"{' '.join(cmd[:6])} ... exit {r.returncode}\n{r.stdout[-3000:]}\n{r.stderr[-4000:]}"
    )
    return r  # type: ignore[no-any-return]


class Stack:
    """One compose project of docker-compose.yml with the stand-ins laid over it; `env` holds
    every variable the file reads (the process's environment outranks any .env in the tree)."""

    def __init__(self, name: str, env: dict[str, str], overrides: list[Path]) -> None:
        self.name = name
        self.env = {**os.environ, **env}
        files = [ROOT / "docker-compose.yml", STAND_INS, *overrides]
        self.base = ["docker-compose", "-p", name] + [a for f in files for a in ("-f", str(f))]

    def compose(
        self, *args: str, timeout: float = 300, check: bool = True
    ) -> subprocess.CompletedProcess[str]:
        """`docker-compose` on this project, in the repository (the file's relative paths)."""
        return run([*self.base, *args], timeout=timeout, env=self.env, cwd=ROOT, check=check)

    def container(self, service: str) -> str:
        """The id of a service's (first) container."""
        return self.compose("ps", "-q", service).stdout.split()[0]

    def state(self, service: str, field: str) -> str:
        """A field of a service's container state (`Health.Status`, `ExitCode`, ...)."""
        fmt = "{{.State." + field + "}}"
        return run(
            ["docker", "inspect", "-f", fmt, self.container(service)], timeout=30
        ).stdout.strip()

    def logs(self) -> str:
        """The last lines of every service's output, for a failure's message."""
        demo = ("--profile", "demo")
        return self.compose(*demo, "logs", "--no-color", "--tail", "40", check=False).stdout[
            -12000:
        ]

    def down(self) -> None:
        """Stop and remove the project's containers, networks and volumes."""
        self.compose("--profile", "demo", "down", "-v", "--remove-orphans", check=False)
