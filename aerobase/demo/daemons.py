"""The daemons' configuration files the demo writes: TOML, the encrypted asset files, the password."""

from __future__ import annotations

import base64
from pathlib import Path
from typing import Any

# the UAV's camera description (asset attributes) and the agent's [video]: the simulated downward
# camera's 640x480 render at 15 fps, a rate the demo's 2-core budget affords beside everything else
DEMO_CAMERA = {"width": 640, "height": 480, "fps": 15}


def write_secret(path: Path, data: bytes | str) -> None:
    """Write a file only its owner may read."""
    path.write_bytes(data if isinstance(data, bytes) else data.encode())
    path.chmod(0o600)


def write_daemon_files(
    folder: Path,
    ports: dict[str, int],
    speed: float,
    asset_password: str,
    base: dict[str, Any],
    uav: dict[str, Any],
    autopilot_url: str,
    steering: str = "agent",
) -> None:
    """Everything the two daemons read at start: their assets' files (as the API returned them
    on registration), the password that opens them, and base.toml / agent.toml (the agent flies
    the autopilot at `autopilot_url`)."""
    write_secret(folder / "asset-password", asset_password)
    write_secret(folder / "base.abcf", base64.b64decode(base["config_file"]))
    write_secret(folder / "uav.abcf", base64.b64decode(uav["config_file"]))
    (folder / "base.toml").write_text(base_toml(folder, ports, speed))
    (folder / "agent.toml").write_text(agent_toml(folder, ports, autopilot_url, steering))


def base_toml(folder: Path, ports: dict[str, int], speed: float) -> str:
    """The landing-base daemon's configuration: the simulated PLC and GNSS, motion at `speed`."""
    return f"""# written by aerobase demo
telemetry_hz = 2.0

[plc]
host = "127.0.0.1"
port = {ports["plc"]}
poll_hz = 10.0

[motion]
panels_travel_s = {12.0 / speed:.3f}
lift_travel_s = {8.0 / speed:.3f}

[uav]
min_mass_g = 1200.0
max_mass_g = 1800.0
scale_tare_g = 15.0
stable_s = {max(0.5, 3.0 / speed):.2f}

[server]
config_file = "{folder / "base.abcf"}"
password_file = "{folder / "asset-password"}"
state_file = "{folder / "base-link.db"}"

[rtk]
tcp_host = "127.0.0.1"
tcp_port = {ports["gnss"]}
"""


def agent_toml(
    folder: Path, ports: dict[str, int], autopilot_url: str, steering: str = "agent"
) -> str:
    """The UAV agent's configuration: the autopilot at `autopilot_url`, precision landing when the
    world serves a camera and an IR sensor, its descent steered by `steering` (agent, autopilot)."""
    return f"""# written by aerobase demo
[server]
config_file = "{folder / "uav.abcf"}"
password_file = "{folder / "asset-password"}"
state_file = "{folder / "agent-link.db"}"

[autopilot]
url = "{autopilot_url}"

[telemetry]
rate_hz = 5
""" + (
        f"""
[precland]
camera_port = {ports["camera"]}
ir_port = {ports["ir"]}
steering = "{steering}"

[video]
enabled = true
width = {DEMO_CAMERA["width"]}
height = {DEMO_CAMERA["height"]}
fps = {DEMO_CAMERA["fps"]}
allow_loopback_ice = true
"""
        if "camera" in ports and "ir" in ports
        else ""
    )
