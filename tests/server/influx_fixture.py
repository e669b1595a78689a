"""A real influxd (1.x) of the test session's own: free port, temporary directories, no system service.

Import `influxdb_url` into a conftest (or a test module) to get the URL of a running server with
the database `aerobase` created. One process serves every importer (reference-counted).
"""

from __future__ import annotations

import os
import shutil
import subprocess
import tempfile
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import httpx
import pytest

from aerobase.ports import free_port

DATABASE = "aerobase"
START_TIMEOUT_S = 30.0


def _config(root: Path, http_port: int, rpc_port: int) -> str:
    """An influxd 1.x config: data under `root`, HTTP on 127.0.0.1 only, nothing else listening."""
    return f"""\
reporting-enabled = false
bind-address = "127.0.0.1:{rpc_port}"

[meta]
  dir = "{root}/meta"
  logging-enabled = false

[data]
  dir = "{root}/data"
  wal-dir = "{root}/wal"
  query-log-enabled = false
  wal-fsync-delay = "0s"

[monitor]
  store-enabled = false

[subscriber]
  enabled = false

[continuous_queries]
  enabled = false

[http]
  enabled = true
  bind-address = "127.0.0.1:{http_port}"
  auth-enabled = false
  log-enabled = false
  pprof-enabled = false
  unix-socket-enabled = false

[ifql]
  enabled = false

[logging]
  level = "warn"
"""


class Influxd:
    """One influxd child process with its own directory, config and port."""

    def __init__(self, binary: str) -> None:
        self.binary = binary
        self._tmp = tempfile.TemporaryDirectory(prefix="aerobase-influxd-")
        self.root = Path(self._tmp.name)
        self.port = free_port()
        self.url = f"http://127.0.0.1:{self.port}"
        self.proc: subprocess.Popen[bytes] | None = None

    def start(self) -> Influxd:
        """Write the config, start the process, wait until /ping answers, create the database."""
        config = self.root / "influxdb.conf"
        config.write_text(_config(self.root, self.port, free_port()))
        log = (self.root / "influxd.log").open("wb")
        self.proc = subprocess.Popen(
            [self.binary, "-config", str(config)],
            stdout=log,
            stderr=subprocess.STDOUT,
            stdin=subprocess.DEVNULL,
            start_new_session=True,
        )
        log.close()
        deadline = time.monotonic() + START_TIMEOUT_S
        while not self._ping():
            if self.proc.poll() is not None or time.monotonic() > deadline:
                output = (self.root / "influxd.log").read_text(errors="replace")[-2000:]
                self.stop()
                raise RuntimeError(f"influxd did not answer /ping on {self.url}:\n{output}")
            time.sleep(0.05)
        r = httpx.post(f"{self.url}/query", data={"q": f'CREATE DATABASE "{DATABASE}"'}, timeout=10)
        r.raise_for_status()
        return self

    def _ping(self) -> bool:
        try:
            return httpx.get(f"{self.url}/ping", timeout=1).status_code == 204
        except httpx.HTTPError:
            return False

    def stop(self) -> None:
        """Terminate the process and remove its directory."""
        if self.proc is not None and self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(15)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait(5)
        self._tmp.cleanup()


_lock = threading.Lock()
_shared: Influxd | None = None
_users = 0


def _acquire() -> Influxd:
    global _shared, _users
    with _lock:
        if _shared is None:
            binary = shutil.which("influxd")
            if binary is None:
                reason = "influxd is not installed (run .ci/install-influxdb.sh)"
                if os.environ.get("CI", "").lower() == "true":
                    pytest.fail(f"{reason}; CI=true: the InfluxDB tests must run")
                pytest.skip(f"{reason}; outside CI this skips, under CI=true it fails")
            _shared = Influxd(binary).start()
        _users += 1
        return _shared


def _release() -> None:
    global _shared, _users
    with _lock:
        _users -= 1
        if _users == 0 and _shared is not None:
            _shared.stop()
            _shared = None


@pytest.fixture(scope="session")
def influxdb_url() -> Iterator[str]:
    """The URL of a running influxd 1.x of this test session (database `aerobase` exists)."""
    server = _acquire()
    try:
        yield server.url
    finally:
        _release()
