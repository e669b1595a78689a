"""The companion-computer daemon's configuration (`agent.toml`), validated at start."""

from __future__ import annotations

import tomllib
from pathlib import Path
from typing import Literal

from pydantic import BaseModel, ConfigDict, Field, field_validator

from asset_agent.precland.config import PrecisionLandingConfig
from assetlink.rtk import parse_source


class ServerSection(BaseModel):
    """How to reach the server: the encrypted asset file and where the link keeps its state."""

    model_config = ConfigDict(extra="forbid")
    config_file: Path = Path("~/.aerobase/asset.enc")
    password_file: Path | None = None  # else AEROBASE_ASSET_PASSWORD, else a prompt
    state_file: Path = Path("~/.aerobase/agent-link.db")
    url: str | None = None  # overrides the server URL written in the asset file
    max_outbox: int = Field(default=200_000, ge=100)


class AutopilotSection(BaseModel):
    """The MAVLink connection to the autopilot (pymavlink URL: udpin:, udpout:, tcp:, serial device)."""

    model_config = ConfigDict(extra="forbid")
    url: str = "tcp:127.0.0.1:5760"
    link_timeout_s: float = Field(default=3.0, gt=0)
    command_timeout_s: float = Field(default=1.5, gt=0)


class TelemetrySection(BaseModel):
    """What is reported to the server and when."""

    model_config = ConfigDict(extra="forbid")
    rate_hz: float = Field(default=5.0, gt=0, le=50)
    low_battery_pct: float = Field(default=30.0, ge=0, le=100)


class AvailabilitySection(BaseModel):
    """Limits of the UAV's availability check."""

    model_config = ConfigDict(extra="forbid")
    min_battery_pct: float = Field(default=80.0, ge=0, le=100)
    min_fix_type: int = Field(default=3, ge=0, le=6)


class PreclandSection(PrecisionLandingConfig):
    """`[precland]`: the precision-landing pipeline's parameters plus where its sensors are.

    `enabled` defaults to on when a camera or IR address is given. The pad's surveyed position is
    the autopilot's home ("home", the base's pad) or `pad_lat`/`pad_lon` ("surveyed"). `clock_rate`
    is sensor-clock seconds per wall second (None: measured from the sensors' timestamps).
    """

    mode: Literal["landing_target", "companion"] = "landing_target"
    enabled: bool | None = None
    camera_host: str = "127.0.0.1"
    camera_port: int | None = Field(default=None, ge=1, le=65535)
    ir_host: str = "127.0.0.1"
    ir_port: int | None = Field(default=None, ge=1, le=65535)
    activation_height_m: float = Field(default=10.0, gt=0)
    pad_source: Literal["home", "surveyed"] = "home"
    pad_lat: float | None = Field(default=None, ge=-90, le=90)
    pad_lon: float | None = Field(default=None, ge=-180, le=180)
    pad_sigma_m: float = Field(default=1.0, gt=0)
    # a LAND farther than this from the pad is not a landing on it (a contingency landing in the
    # field, a failsafe's LAND far out): the autopilot lands as it will, no search flies to the pad
    pad_reach_m: float = Field(default=50.0, gt=0)
    state_rate_hz: float = Field(default=25.0, gt=0, le=100)
    clock_rate: float | None = Field(default=None, gt=0)

    @property
    def active(self) -> bool:
        """True when the daemon should run precision landing."""
        if self.enabled is not None:
            return self.enabled
        return self.camera_port is not None or self.ir_port is not None

    def pipeline(self) -> PrecisionLandingConfig:
        """The pipeline's own configuration."""
        return PrecisionLandingConfig(
            **{k: getattr(self, k) for k in PrecisionLandingConfig.model_fields}
        )


class VideoSection(BaseModel):
    """`[video]`: live video, encoded once on board (VP8) and published to the server with WHIP.

    The source is a video file (`file`, looped) or the downward camera's frame stream (by default
    the one precision landing reads). Size and rate should match the asset's camera description.
    `allow_loopback_ice` is for a server on the same loopback-only host (tests, the demo).
    """

    model_config = ConfigDict(extra="forbid")
    enabled: bool = False
    camera_host: str | None = None  # default: [precland] camera_host
    camera_port: int | None = Field(default=None, ge=1, le=65535)  # default: [precland]'s
    file: Path | None = None
    width: int = Field(default=640, ge=16, le=7680)
    height: int = Field(default=480, ge=16, le=4320)
    fps: float = Field(default=30.0, gt=0, le=120)
    allow_loopback_ice: bool = False


class RtkSection(BaseModel):
    """`[rtk]`: the base's RTCM3 stream on the site's network (base_station `[rtk] serve_port`),
    injected first; the server's relay only while it is silent (corrections.py). Empty: the
    server's relay alone."""

    model_config = ConfigDict(extra="forbid")
    local_source: str = ""  # e.g. "tcp://192.168.1.10:2102"
    local_silence_s: float = Field(default=3.0, gt=0)

    @field_validator("local_source")
    @classmethod
    def _valid_source(cls, value: str) -> str:
        if value:
            parse_source(value)
        return value


class MetricsSection(BaseModel):
    """The agent's own Prometheus /metrics (assetlink/metrics.py): off unless a port is set;
    on this machine only unless `host` says otherwise."""

    model_config = ConfigDict(extra="forbid")
    port: int = Field(default=0, ge=0, le=65535)  # e.g. 9102
    host: str = "127.0.0.1"


class AgentConfig(BaseModel):
    """All of agent.toml."""

    model_config = ConfigDict(extra="forbid")
    server: ServerSection = ServerSection()
    autopilot: AutopilotSection = AutopilotSection()
    telemetry: TelemetrySection = TelemetrySection()
    availability: AvailabilitySection = AvailabilitySection()
    precland: PreclandSection = PreclandSection()
    video: VideoSection = VideoSection()
    rtk: RtkSection = RtkSection()
    metrics: MetricsSection = MetricsSection()

    @classmethod
    def load(cls, path: str | Path) -> AgentConfig:
        """Parse and validate a TOML file."""
        with open(path, "rb") as f:
            return cls.model_validate(tomllib.load(f))
