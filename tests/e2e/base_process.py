"""The landing-base daemon as a real process (`aerobase base-station`), for tests that kill it.

Its configuration is the in-process one (`StationConfig`) written as TOML, with the asset file the
server issued and the password in a 0600 file, as an installation has them.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
from pathlib import Path

from base_station.config import StationConfig


def write_toml(config: StationConfig, path: Path) -> None:
    """`config` as a TOML file (every section; strings and numbers in their JSON spelling)."""
    lines = [f"telemetry_hz = {config.telemetry_hz}"]
    for section, values in config.model_dump(exclude={"telemetry_hz"}).items():
        lines.append(f"\n[{section}]")
        lines += [f"{key} = {json.dumps(value)}" for key, value in values.items()]
    path.write_text("\n".join(lines) + "\n")


class BaseDaemon:
    """`aerobase base-station --config <folder>/base.toml`: start, SIGKILL, start again, stop."""

    def __init__(
        self, config: StationConfig, asset_file: bytes, password: str, folder: Path
    ) -> None:
        folder.mkdir(parents=True, exist_ok=True)
        (folder / "base.abcf").write_bytes(asset_file)
        secret = folder / "asset-password"
        secret.write_text(password)
        secret.chmod(0o600)
        server = config.server.model_copy(
            update={
                "config_file": str(folder / "base.abcf"),
                "password_file": str(secret),
                "state_file": str(folder / "base-link.db"),
            }
        )
        self.toml = folder / "base.toml"
        write_toml(config.model_copy(update={"server": server}), self.toml)
        self.log = folder / "base.log"
        self.proc: subprocess.Popen[bytes] | None = None
        self.starts = 0

    def start(self) -> None:
        """Start the daemon process (its output goes to base.log)."""
        exe = Path(sys.executable).parent / "aerobase"
        with open(self.log, "ab") as out:
            self.proc = subprocess.Popen(
                [str(exe), "base-station", "--config", str(self.toml)],
                stdout=out,
                stderr=subprocess.STDOUT,
                env={**os.environ, "PYTHONUNBUFFERED": "1"},
            )
        self.starts += 1

    def kill(self) -> None:
        """SIGKILL: no clean shutdown, no MOTION_STOP, the PLC's watchdog stops being fed."""
        if self.proc is not None:
            self.proc.send_signal(signal.SIGKILL)
            self.proc.wait(10)
            self.proc = None

    def stop(self) -> None:
        """SIGTERM, as a service manager stops it."""
        if self.proc is not None:
            self.proc.terminate()
            try:
                self.proc.wait(20)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait(5)
            self.proc = None

    def output(self) -> str:
        """What the daemon logged (for failure messages)."""
        return self.log.read_text(errors="replace") if self.log.exists() else ""
