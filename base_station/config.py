"""Configuration of the landing-base daemon: a pydantic model loaded from a TOML file.

Example `base.toml` (every key optional; these are the defaults)::

    telemetry_hz = 2.0

    [plc]
    host = "127.0.0.1"
    port = 502            # 5020 for the simulator
    unit = 1
    poll_hz = 5.0
    timeout_s = 1.0
    watchdog_period_s = 0.25
    reconnect_s = 0.5
    heartbeat_timeout_s = 1.0   # PLC_HEARTBEAT frozen this long = PLC not running = link down

    [motion]
    panels_travel_s = 12.0
    lift_travel_s = 8.0
    timeout_factor = 1.5   # the daemon gives up after travel * factor + margin
    timeout_margin_s = 2.0
    link_wait_s = 5.0      # with the PLC link down, a motion command waits this long for it

    [weather]
    max_wind_mps = 8.0
    max_gust_mps = 12.0
    max_rain_mm_h = 0.0
    min_temperature_c = -5.0
    max_temperature_c = 40.0

    [uav]
    min_mass_g = 1200.0
    max_mass_g = 1800.0
    scale_tare_g = 0.0
    stable_s = 3.0
    stable_tolerance_g = 50.0

    [charge]
    current_limit_ma = 5000

    [server]
    config_file = ""      # the encrypted asset configuration file ("" = no server link)
    password_file = ""    # else AEROBASE_ASSET_PASSWORD, else a prompt
    state_file = "~/.aerobase/base-link.db"
    url = ""              # overrides the server URL in the asset file

    [rtk]
    tcp_host = "127.0.0.1"  # or serial_device = "/dev/ttyACM0"
    tcp_port = 5021
    serial_device = ""
    baudrate = 115200

    [metrics]
    port = 0              # Prometheus /metrics of this daemon (0 = off), e.g. 9101
    host = "127.0.0.1"    # listen on this machine only unless a scraper elsewhere needs it
"""

from __future__ import annotations

import tomllib
from pathlib import Path

from pydantic import BaseModel, ConfigDict, Field, model_validator


class _Section(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)


class PlcConfig(_Section):
    """Where the PLC is and how often to talk to it."""

    host: str = "127.0.0.1"
    port: int = Field(default=502, ge=0, le=65535)
    unit: int = Field(default=1, ge=0, le=255)
    poll_hz: float = Field(default=5.0, ge=5.0, le=50.0)
    timeout_s: float = Field(default=1.0, gt=0)
    watchdog_period_s: float = Field(default=0.25, gt=0, le=0.5)
    reconnect_s: float = Field(default=0.5, gt=0)
    heartbeat_timeout_s: float = Field(default=1.0, ge=0.3)


class MotionConfig(_Section):
    """Travel times of the panels and the lift (wall seconds on the real base)."""

    panels_travel_s: float = Field(default=12.0, gt=0)
    lift_travel_s: float = Field(default=8.0, gt=0)
    timeout_factor: float = Field(default=1.5, ge=1.0)
    timeout_margin_s: float = Field(default=2.0, ge=0)
    # a motion command that finds the PLC link down waits this long for it to come back before
    # it is refused (a missed poll, a frozen heartbeat, a cable blip must not fail a run's
    # close with the UAV on the lift); 0 refuses at once
    link_wait_s: float = Field(default=5.0, ge=0, le=60)


class WeatherLimits(_Section):
    """Flight limits checked by `check_availability`."""

    max_wind_mps: float = 8.0
    max_gust_mps: float = 12.0
    max_rain_mm_h: float = 0.0
    min_temperature_c: float = -5.0
    max_temperature_c: float = 40.0


class UavConfig(_Section):
    """The UAV this base hosts: its mass window on the scale and the stability rule."""

    min_mass_g: float = 1200.0
    max_mass_g: float = 1800.0
    scale_tare_g: float = 0.0
    stable_s: float = Field(default=3.0, ge=0)
    stable_tolerance_g: float = Field(default=50.0, gt=0)

    @model_validator(mode="after")
    def _window(self) -> UavConfig:
        if self.min_mass_g >= self.max_mass_g:
            raise ValueError("uav.min_mass_g must be below uav.max_mass_g")
        return self


class ChargeConfig(_Section):
    """Default charge current limit, and how long the charger may take to report charging."""

    current_limit_ma: int = Field(default=5000, ge=0, le=65535)
    start_timeout_s: float = Field(default=10.0, gt=0, le=600)


class ServerConfig(_Section):
    """The server link: the encrypted asset file (empty: run without a server) and the link's state."""

    config_file: str = (
        ""  # e.g. "~/.aerobase/asset.enc"; password from password_file or AEROBASE_ASSET_PASSWORD
    )
    password_file: str = ""  # mode 0600
    state_file: str = "~/.aerobase/base-link.db"  # the link's outbox, session and command ledger
    url: str = ""  # overrides the server URL written in the asset file


class RtkConfig(_Section):
    """Where the base GNSS receiver's RTCM3 stream comes from, and where the base serves it on
    the site's network (rtcm_server.py: off unless `serve_port` is set)."""

    tcp_host: str = "127.0.0.1"
    tcp_port: int = Field(default=5021, ge=0, le=65535)
    serial_device: str = ""
    baudrate: int = 115200
    serve_host: str = "0.0.0.0"
    serve_port: int = Field(default=0, ge=0, le=65535)


class MetricsConfig(_Section):
    """The daemon's own Prometheus /metrics (assetlink/metrics.py): off unless a port is set."""

    port: int = Field(default=0, ge=0, le=65535)
    host: str = "127.0.0.1"


class StationConfig(_Section):
    """The whole daemon configuration."""

    telemetry_hz: float = Field(default=2.0, ge=1.0, le=5.0)
    plc: PlcConfig = Field(default_factory=PlcConfig)
    motion: MotionConfig = Field(default_factory=MotionConfig)
    weather: WeatherLimits = Field(default_factory=WeatherLimits)
    uav: UavConfig = Field(default_factory=UavConfig)
    charge: ChargeConfig = Field(default_factory=ChargeConfig)
    server: ServerConfig = Field(default_factory=ServerConfig)
    rtk: RtkConfig = Field(default_factory=RtkConfig)
    metrics: MetricsConfig = Field(default_factory=MetricsConfig)


def load_config(path: str | Path) -> StationConfig:
    """Read and validate a TOML configuration file."""
    with open(path, "rb") as f:
        data = tomllib.load(f)
    return StationConfig.model_validate(data)
