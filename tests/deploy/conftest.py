"""What the deployment tests share: the programs the deployment runs (installed by
.ci/install-system.sh); a PostgreSQL database of each test's own is tests/conftest.py's
`own_database`, whose superuser is ROOT_EMAIL."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

from tests.conftest import IN_CI, OWN_DATABASE_ROOT

ROOT_EMAIL = OWN_DATABASE_ROOT
TURN_CONF = Path(__file__).resolve().parents[2] / "deploy" / "coturn" / "turnserver.conf"


def conf_relay_ports() -> tuple[int, int]:
    """deploy/coturn/turnserver.conf's relay ports: its min-port and max-port."""
    conf = TURN_CONF.read_text()
    low, high = (int(conf.split(f"{k}=")[1].split()[0]) for k in ("min-port", "max-port"))
    return low, high


def program(name: str, package: str) -> str:
    """The path of a program from a Debian package; missing, it fails in CI and skips elsewhere."""
    found = shutil.which(name) or shutil.which(name, path="/usr/sbin:/sbin")
    if found is None:
        message = f"{name} is not installed (Debian's {package} package)"
        if IN_CI:
            pytest.fail(f"{message}; CI=true: .ci/install-system.sh installs it")
        pytest.skip(f"{message}; in CI this fails instead")
    return found
