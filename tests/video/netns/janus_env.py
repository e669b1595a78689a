"""Debian's Janus for the Janus-path cases, inside the private network test_video_janus.py builds.

Janus's ICE will not use loopback, so these cases run in a network namespace with a veth pair
(198.18.0.1 and 198.18.0.2, the benchmarking range); nothing can leave it.
"""

from __future__ import annotations

import os
import shutil
import socket
import subprocess
from dataclasses import dataclass
from pathlib import Path

import httpx

from tests.polling import wait_for

JANUS_LIBS = Path("/usr/lib/x86_64-linux-gnu/janus")
NETNS_ADDRESS = "198.18.0.1"
RTP_PORTS = (21000, 21100)
DEPLOYED_STREAMING = (
    Path(__file__).resolve().parents[3] / "deploy/janus/janus.plugin.streaming.jcfg"
)
DEPLOYED_RANGE = 'rtp_port_range = "20100-20199"'


def in_private_network() -> bool:
    """True inside the namespace test_video_janus.py builds (the veth address is ours)."""
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        try:
            s.bind((NETNS_ADDRESS, 0))
        except OSError:
            return False
    return True


@dataclass
class Janus:
    """A running Janus with the HTTP transport and the Streaming plugin only."""

    folder: Path
    http_port: int
    proc: subprocess.Popen[bytes] | None = None

    @property
    def url(self) -> str:
        return f"http://127.0.0.1:{self.http_port}/janus"

    def write_config(self) -> None:
        for kind, lib in (("plugins", "libjanus_streaming.so"), ("transports", "libjanus_http.so")):
            d = self.folder / kind
            d.mkdir(parents=True, exist_ok=True)
            if not (d / lib).exists():
                (d / lib).symlink_to(JANUS_LIBS / kind / lib)
        cfg = self.folder / "cfg"
        cfg.mkdir(exist_ok=True)
        (cfg / "janus.jcfg").write_text(
            "general: {\n"
            f'  configs_folder = "{cfg}"\n'
            f'  plugins_folder = "{self.folder / "plugins"}"\n'
            f'  transports_folder = "{self.folder / "transports"}"\n'
            "  debug_level = 4\n"
            "  session_timeout = 60\n"
            "}\n"
            'media: {\n  rtp_port_range = "20000-20999"\n}\n'
            'nat: {\n  ice_enforce_list = "v0"\n}\n'
        )
        (cfg / "janus.transport.http.jcfg").write_text(
            "general: {\n"
            '  base_path = "/janus"\n  http = true\n'
            f'  port = {self.http_port}\n  ip = "127.0.0.1"\n  https = false\n'
            "}\nadmin: {\n  admin_http = false\n}\n"
        )
        # the deployment's own streaming configuration, only its port range changed
        deployed = DEPLOYED_STREAMING.read_text()
        assert DEPLOYED_RANGE in deployed, f"{DEPLOYED_STREAMING} no longer sets {DEPLOYED_RANGE}"
        ours = f'rtp_port_range = "{RTP_PORTS[0]}-{RTP_PORTS[1]}"'
        (cfg / "janus.plugin.streaming.jcfg").write_text(deployed.replace(DEPLOYED_RANGE, ours))

    def start(self) -> Janus:
        """Start Janus and wait until its HTTP API answers."""
        janus = shutil.which("janus") or "/usr/bin/janus"
        assert os.path.exists(janus), "janus is not installed (.ci/install-system.sh)"
        self.write_config()
        log = open(self.folder / "janus.log", "ab")
        cfg = self.folder / "cfg"
        self.proc = subprocess.Popen(
            [janus, "-C", str(cfg / "janus.jcfg"), "-F", str(cfg)], stdout=log, stderr=log
        )
        wait_for(self.answers, 15, what=f"Janus's HTTP API (log: {self.folder / 'janus.log'})")
        return self

    def answers(self) -> bool:
        """True when the HTTP API answers."""
        try:
            r = httpx.post(self.url, json={"janus": "info", "transaction": "up"}, timeout=1)
        except httpx.HTTPError:
            return False
        return r.status_code == 200

    def stop(self) -> None:
        if self.proc is not None and self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(10)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait(5)
