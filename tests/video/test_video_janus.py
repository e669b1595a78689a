"""The Janus path end to end: Debian's Janus, the server, an RTP-sending agent and viewers, all
in a private network namespace (Janus's ICE will not use loopback)."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

pytestmark = pytest.mark.slow
ROOT = Path(__file__).resolve().parents[2]
CASES = (
    "tests/video/netns/janus_cases.py tests/video/netns/janus_console_cases.py "
    "tests/video/netns/janus_replica_cases.py"
)
# a veth pair inside a new network namespace: 198.18.0.1 (v0, Janus's) and 198.18.0.2 (v1)
NETWORK = (
    "ip link set lo up && ip link add v0 type veth peer name v1 && "
    "ip addr add 198.18.0.1/24 dev v0 && ip addr add 198.18.0.2/24 dev v1 && "
    "ip link set v0 up && ip link set v1 up"
)


def test_the_janus_path_in_a_private_network():
    assert shutil.which("unshare") and shutil.which("ip"), "needs util-linux and iproute2"
    env = {k: v for k, v in os.environ.items() if k not in ("DATABASE_URL", "REDIS_URL")}
    env["PYTHONPATH"] = str(ROOT)
    cmd = f"{NETWORK} && exec {sys.executable} -m pytest {CASES} -p no:cacheprovider -q -x"
    r = subprocess.run(
        ["unshare", "-n", "sh", "-c", cmd],
        cwd=ROOT,
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert r.returncode == 0, r.stdout[-6000:] + r.stderr[-3000:]
    assert " passed" in r.stdout and "failed" not in r.stdout, r.stdout[-3000:]
