"""A Python client generated from the live server's OpenAPI document (openapi-python-client), as a
front-end or integration developer would make one: the document is the only input."""

from __future__ import annotations

import importlib
import subprocess
import sys
import tempfile
from pathlib import Path
from types import ModuleType

import httpx

PACKAGE = "aerobase_client"
# the generator reads JSON and multipart bodies; the waypoint-file import's text bodies, the video
# API's SDP offers and answers, trickle-ICE fragments, recorded segments and their frame times are
# raw bytes to it (its documented way for media types it does not know)
CONFIG = f"""\
project_name_override: aerobase-client
package_name_override: {PACKAGE}
post_hooks: []
content_type_overrides:
  text/plain: application/octet-stream
  application/vnd.mavlink.wpl: application/octet-stream
  application/sdp: application/octet-stream
  application/trickle-ice-sdpfrag: application/octet-stream
  video/webm: application/octet-stream
  application/jsonl: application/octet-stream
"""
_generated: dict[str, ModuleType] = {}


def generate(server_url: str) -> ModuleType:
    """Generate the client from `server_url`'s /api/openapi.json (once per test process) and import
    it. Fails on any generator warning: a part of the document a client cannot use is a defect."""
    if PACKAGE in _generated:
        return _generated[PACKAGE]
    where = Path(tempfile.mkdtemp(prefix="aerobase-client-"))
    document = httpx.get(f"{server_url}/api/openapi.json", timeout=30)
    document.raise_for_status()
    (where / "openapi.json").write_bytes(document.content)
    (where / "config.yaml").write_text(CONFIG)
    done = subprocess.run(
        [
            *(sys.executable, "-m", "openapi_python_client", "generate"),
            *("--path", str(where / "openapi.json")),
            *("--config", str(where / "config.yaml")),
            *("--meta", "none", "--fail-on-warning"),
            *("--output-path", str(where / PACKAGE)),
        ],
        capture_output=True,
        text=True,
        timeout=120,
        cwd=where,
    )
    assert done.returncode == 0, f"the generator refused the document:\n{done.stdout}{done.stderr}"
    sys.path.insert(0, str(where))
    _generated[PACKAGE] = importlib.import_module(PACKAGE)
    return _generated[PACKAGE]


def part(client: ModuleType, name: str) -> ModuleType:
    """A module of the generated client, e.g. part(c, "api.missions.create_mission")."""
    return importlib.import_module(f"{client.__name__}.{name}")
