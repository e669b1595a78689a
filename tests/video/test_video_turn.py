"""Through coturn: a relay-only viewer gets frames with the server's time-limited credentials."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import httpx
import pytest

from aerobase.ports import free_port
from tests.conftest import LiveServer, Tenant, test_settings
from tests.polling import wait_for
from tests.video.peers import publisher
from tests.video.test_video_api import uav_with_camera

pytestmark = pytest.mark.slow
SECRET = "coturn-test-static-auth-secret"


@pytest.fixture(scope="module")
def coturn(tmp_path_factory: pytest.TempPathFactory) -> Iterator[tuple[int, Path]]:
    """Debian's coturn (.ci/install-system.sh) on loopback, `use-auth-secret`, verbose log."""
    turnserver = shutil.which("turnserver") or "/usr/bin/turnserver"
    assert os.path.exists(turnserver), "coturn is not installed (.ci/install-system.sh)"
    tmp = tmp_path_factory.mktemp("coturn")
    port = free_port()
    relay = free_port()
    # coturn takes no comment on a setting's line; loopback peers only because this is a test
    conf = "\n".join(
        [
            "listening-ip=127.0.0.1",
            f"listening-port={port}",
            "relay-ip=127.0.0.1",
            f"min-port={relay}",
            f"max-port={relay + 40}",
            "use-auth-secret",
            f"static-auth-secret={SECRET}",
            "realm=aerobase.test",
            "allow-loopback-peers",
            "no-tls",
            "no-dtls",
            "no-cli",
            "fingerprint",
            "verbose",
            f"pidfile={tmp / 'turnserver.pid'}",
            f"userdb={tmp / 'turndb'}",
            f"log-file={tmp / 'turn.log'}",
            "simple-log",
        ]
    )
    (tmp / "turn.conf").write_text(conf + "\n")
    log = tmp / "turn.log"
    proc = subprocess.Popen(
        [turnserver, "-c", str(tmp / "turn.conf")],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    try:
        wait_for(
            lambda: log.exists() and "UDP listener opened on" in log.read_text(errors="replace"),
            15,
            what="coturn listening",
        )
        yield port, log
    finally:
        proc.terminate()
        proc.wait(10)


@pytest.fixture(scope="module")
def turn_server(database_url: str, coturn: tuple[int, Path]) -> Iterator[LiveServer]:
    port, _ = coturn
    server = LiveServer(
        test_settings(
            database_url,
            video_ice_loopback=True,
            video_turn_urls=[f"turn:127.0.0.1:{port}?transport=udp"],
            video_turn_secret=SECRET,
        )
    ).start()
    yield server
    server.stop()


async def test_a_relay_only_viewer_gets_frames_through_coturn(
    turn_server: LiveServer, coturn: tuple[int, Path], superuser_email: str
):
    with httpx.Client(base_url=turn_server.url, timeout=30) as api:
        tenant = Tenant(api, superuser_email, label="turn")
        asset_id, asset_token = uav_with_camera(tenant, api)
    pub = publisher(turn_server.url, asset_id, asset_token, 320, 240, 20)
    await pub.publish_once()
    try:
        env = {**os.environ, "PYTHONPATH": os.environ.get("PYTHONPATH", os.getcwd())}
        args = [turn_server.url, asset_id, tenant.tokens["viewer"], "30"]
        proc = await _run([sys.executable, "-m", "tests.video.relay_only_viewer", *args], env)
        result = json.loads(proc.strip().splitlines()[-1])
        assert result.get("error") is None, result
        assert result["candidate_types"] == ["relay"], result  # no host candidate at all
        assert result["frames"] >= 30 and result["sizes"] == ["320x240"], result
        # coturn accepted the server's REST credentials (username "expiry:user id") and relayed
        text = coturn[1].read_text(errors="replace")
        user = tenant.user_ids["viewer"]
        assert f":{user}" in text and "ALLOCATE processed, success" in text, text[-3000:]
    finally:
        await pub.stop()
        await pub.track.aclose()  # type: ignore[attr-defined]


async def _run(cmd: list[str], env: dict[str, str]) -> str:
    import asyncio

    proc = await asyncio.create_subprocess_exec(
        *cmd, env=env, stdout=asyncio.subprocess.PIPE, stderr=asyncio.subprocess.PIPE
    )
    out, err = await asyncio.wait_for(proc.communicate(), 90)
    assert proc.returncode == 0, err.decode()[-3000:]
    return out.decode()
