"""The media services of docker-compose.yml run with the very configuration files it mounts:
Debian's janus with deploy/janus/ (the HTTP API up, the streaming plugin alone), and Debian's
coturn with deploy/coturn/turnserver.conf (a TURN allocation with time-limited credentials
derived from the shared secret is granted on the configured relay ports; a wrong one is not).
Only the listening ports differ, as they do between the compose file and this machine."""

from __future__ import annotations

import asyncio
import base64
import hashlib
import hmac
import shutil
import subprocess
import time
from pathlib import Path

import httpx
import pytest
from aioice import turn
from aioice.stun import TransactionFailed, TransactionTimeout

from aerobase.ports import free_port
from tests.deploy.conftest import TURN_CONF, conf_relay_ports, program
from tests.polling import eventually, wait_for

ROOT = Path(__file__).resolve().parents[2]
JANUS = ROOT / "deploy" / "janus"


def _stop(proc: subprocess.Popen[bytes]) -> None:
    proc.terminate()
    try:
        proc.wait(10)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait()


def test_janus_runs_the_deploy_configuration_with_only_the_streaming_plugin(tmp_path):
    binary = program("janus", "janus")
    folder = tmp_path / "janus"
    shutil.copytree(JANUS, folder)
    port = free_port()
    http = folder / "janus.transport.http.jcfg"
    assert "port = 8088" in http.read_text()
    http.write_text(http.read_text().replace("port = 8088", f"port = {port}"))
    with open(tmp_path / "janus.log", "wb") as log:
        proc = subprocess.Popen([binary, "-F", str(folder)], stdout=log, stderr=subprocess.STDOUT)
    try:

        def info() -> dict | None:  # type: ignore[type-arg]
            if proc.poll() is not None:
                raise AssertionError((tmp_path / "janus.log").read_text()[-3000:])
            try:
                return httpx.get(f"http://127.0.0.1:{port}/janus/info", timeout=1).json()  # type: ignore[no-any-return]
            except httpx.HTTPError:
                return None

        body = wait_for(info, 30, "janus's HTTP API")
        assert body["janus"] == "server_info" and body["server-name"] == "aerobase-janus"
        assert set(body["plugins"]) == {"janus.plugin.streaming"}
        assert set(body["transports"]) == {"janus.transport.http"}
    finally:
        _stop(proc)


def _credentials(secret: str, user: str, lifetime_s: int = 600) -> tuple[str, str]:
    """The TURN REST API's time-limited credentials (what the server hands a browser)."""
    username = f"{int(time.time()) + lifetime_s}:{user}"
    digest = hmac.new(secret.encode(), username.encode(), hashlib.sha1).digest()
    return username, base64.b64encode(digest).decode()


def _turnserver(
    binary: str, port: int, secret: str, folder: Path, extra: tuple[str, ...] = ()
) -> subprocess.Popen[bytes]:
    """coturn with deploy/coturn/turnserver.conf on 127.0.0.1:`port`; the secret is passed on the
    command line, as the compose service passes it from .env, and so are `extra` options."""
    with open(folder / "turn.log", "wb") as log:
        return subprocess.Popen(
            [
                binary,
                "-c",
                str(TURN_CONF),
                "--listening-port",
                str(port),
                "--listening-ip",
                "127.0.0.1",
                "--relay-ip",
                "127.0.0.1",
                "--static-auth-secret",
                secret,
                "--userdb",
                str(folder / "turndb"),
                "--pidfile",
                str(folder / "turn.pid"),
                *extra,
            ],
            stdout=log,
            stderr=subprocess.STDOUT,
        )


# the compose file's TURN_MIN_PORT / TURN_MAX_PORT reach coturn as --min-port / --max-port, over
# the file's range: a range set so (below Linux's ephemeral ports, where no test binds) is used
@pytest.mark.parametrize("relay_ports", [None, (30141, 30149)], ids=["file", "command-line"])
async def test_coturn_grants_a_relay_to_credentials_from_the_shared_secret_only(
    tmp_path, relay_ports: tuple[int, int] | None
):
    binary = program("turnserver", "coturn")
    port, secret = free_port(), "a-secret-shared-with-the-server"
    lines = TURN_CONF.read_text().splitlines()
    assert "use-auth-secret" in lines
    assert not any(x.startswith("static-auth-secret") for x in lines)  # never in the file
    low, high = relay_ports or conf_relay_ports()
    extra = (f"--min-port={low}", f"--max-port={high}") if relay_ports else ()
    proc = _turnserver(binary, port, secret, tmp_path, extra)
    try:

        async def allocate(username: str, password: str) -> tuple[str, int] | None:
            if proc.poll() is not None:
                raise AssertionError((tmp_path / "turn.log").read_text()[-3000:])
            try:
                transport, _ = await turn.create_turn_endpoint(
                    asyncio.DatagramProtocol,
                    ("127.0.0.1", port),
                    username,
                    password,
                )
            except (ConnectionRefusedError, TransactionTimeout):
                return None  # not listening yet
            relayed = transport.get_extra_info("sockname")
            transport.close()
            return relayed  # type: ignore[no-any-return]

        relayed = await eventually(
            lambda: allocate(*_credentials(secret, "operator")), 30, "a TURN allocation"
        )
        assert low <= relayed[1] <= high, relayed
        wrong = _credentials("not-the-secret", "operator")
        with pytest.raises(TransactionFailed, match="401"):
            await allocate(*wrong)
        expired_name = f"{int(time.time()) - 60}:operator"
        expired = base64.b64encode(
            hmac.new(secret.encode(), expired_name.encode(), hashlib.sha1).digest()
        ).decode()
        with pytest.raises(TransactionFailed, match="401"):
            await allocate(expired_name, expired)
    finally:
        _stop(proc)
