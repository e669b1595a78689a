"""Settings of the server, read once at start from the environment (pydantic-settings)."""

from __future__ import annotations

from functools import cached_property
from pathlib import Path
from typing import Annotated, Any, Literal

from pydantic import AliasChoices, Field, field_validator, model_validator
from pydantic_settings import BaseSettings, NoDecode, SettingsConfigDict

PLACEHOLDER_SECRETS = {"", "change-me", "changeme", "secret"}


class Settings(BaseSettings):
    """Every setting of `aerobase server`, with a working default for one machine."""

    model_config = SettingsConfigDict(env_prefix="AEROBASE_", extra="ignore", populate_by_name=True)

    environment: Literal["development", "production", "test"] = "development"
    host: str = "127.0.0.1"
    port: int = 8000
    ntrip_port: int | None = Field(
        default=None,
        ge=0,
        le=65535,
        description="TCP port of the NTRIP caster for version 1 and 2 clients (2101 by convention; "
        "0: any free port); unset: only NTRIP 2 clients, on the HTTP port's /ntrip/",
    )
    ntrip_proxy_protocol: bool = Field(
        default=False,
        description="the caster's connections come through a proxy that starts each with a PROXY "
        "protocol v1 line (nginx: proxy_protocol on), whose client address is used; a connection "
        "without one is refused. Off: the client is the connection's peer",
    )
    ntrip_recheck_s: float = Field(
        default=30.0,
        gt=0,
        description="how often an NTRIP stream's account is checked again: one disabled, or no "
        "longer an active member of the organisation, gets no frame after the next check",
    )
    public_url: str | None = Field(
        default=None,
        description="URL daemons use to reach this server; written into asset config files",
    )
    database_url: str = Field(
        default="sqlite+aiosqlite:///./var/aerobase.db",
        validation_alias=AliasChoices("DATABASE_URL", "AEROBASE_DATABASE_URL"),
    )
    redis_url: str | None = Field(
        default=None, validation_alias=AliasChoices("REDIS_URL", "AEROBASE_REDIS_URL")
    )
    db_pool_size: int = Field(
        default=10,
        ge=1,
        description="PostgreSQL connections the requests' pool keeps per server process (each "
        "process also has the ingest's 2 and the telemetry reads' pool)",
    )
    db_max_overflow: int = Field(
        default=20, ge=0, description="connections the requests' pool may open past its size"
    )
    influxdb_url: str | None = Field(
        default=None, validation_alias=AliasChoices("INFLUXDB_URL", "AEROBASE_INFLUXDB_URL")
    )
    migrate_on_start: bool = True
    # browsers' origins allowed to call the API (CORS), e.g. "https://ops.example.com,http://localhost:5173";
    # empty: no cross-origin browser access (same-origin front-ends and non-browser clients need none)
    cors_origins: Annotated[list[str], NoDecode] = Field(default_factory=list)
    # the console's map: a slippy-map tile URL template with {z}, {x}, {y} for sites that have a tile
    # server (e.g. "https://tiles.example.com/{z}/{x}/{y}.png" or a same-origin "/tiles/{z}/{x}/{y}.png");
    # unset: the map is drawn in metres around the base with no tiles and no request leaves the origin
    map_tile_url: str | None = None
    # request bodies over these sizes are refused with 413 before they are read
    max_body_bytes: int = Field(default=1024 * 1024, ge=1024)
    max_import_bytes: int = Field(default=5 * 1024 * 1024, ge=1024)
    http_keep_alive_s: int = Field(
        default=75,
        ge=1,
        description="an idle HTTP/1.1 connection is closed after this many seconds. Keep it above "
        "the reverse proxy's upstream keep-alive (deploy/nginx/aerobase.conf: keepalive_timeout "
        "60s): a proxy that sends a request on a connection the server is just closing answers a "
        "POST with 502",
    )
    http_header_timeout_s: float = Field(
        default=10.0,
        gt=0,
        description="a connection that has not sent a whole request head (the request line and "
        "headers, a WebSocket upgrade's too) this many seconds after it opened, or after the "
        "first byte of its next request, is answered 408 and closed: silent and trickling "
        "clients hold no connection longer",
    )
    forwarded_allow_ips: str = Field(
        default="127.0.0.1",
        validation_alias=AliasChoices("AEROBASE_FORWARDED_ALLOW_IPS", "FORWARDED_ALLOW_IPS"),
        description="the reverse proxy's own address(es) (comma-separated IPs or networks): only "
        "a connection from one of them has its X-Forwarded-For / X-Forwarded-Proto believed, "
        'as the caller\'s address for the login limits and the audit log. Never "*" in '
        "production: any client could then choose its address",
    )
    log_format: Literal["auto", "json", "console"] = "auto"
    log_level: str = "INFO"

    # sessions
    session_ttl_s: int = Field(default=12 * 3600, ge=60)
    session_idle_s: int = Field(default=30 * 60, ge=10)
    asset_session_ttl_s: int = Field(default=7 * 24 * 3600, ge=60)
    asset_session_idle_s: int = Field(default=60, ge=5)

    # asset WebSocket: messages per second per connection (excess rejected with an error)
    ws_rate_per_s: float = Field(default=200.0, gt=0)
    ws_burst: float = Field(default=400.0, ge=1)
    # both WebSockets (frontend_api.md, "Limits of the sockets"): a socket that has not sent its
    # first message (an asset's hello, an operator's first subscribe) within ws_handshake_s, or
    # whose peer has not taken a frame within ws_send_timeout_s, is closed with 4408; the server
    # pings every ws_ping_interval_s and drops a peer whose pong is ws_ping_timeout_s late
    ws_handshake_s: float = Field(default=10.0, gt=0)
    ws_send_timeout_s: float = Field(default=10.0, gt=0)
    ws_ping_interval_s: float = Field(default=10.0, gt=0)
    ws_ping_timeout_s: float = Field(default=10.0, gt=0)
    # what is sent to one socket goes out in one write per ws_flush_interval_s at most (the first
    # frame after a quiet spell at once): fewer, larger writes, at most this much added latency
    ws_flush_interval_s: float = Field(default=0.01, ge=0, le=0.1)
    # an asset's cumulative ack (of what is stored) is sent at most once per ws_ack_interval_s
    ws_ack_interval_s: float = Field(default=0.5, ge=0, le=5)
    # once started, freeze what start-up made and collect cyclic garbage less often
    # (server/kit/gctune.py: full collections over everything imported stopped the loop 0.2-0.4 s)
    gc_tuned: bool = True
    # operator WebSocket: sockets per login session (across replicas), assets followed per socket,
    # messages per second per socket (beyond the burst: error rate_limited and close 4429)
    ws_max_sockets_per_session: int = Field(default=8, ge=1)
    ws_max_subscriptions: int = Field(default=5000, ge=1)
    ws_operator_rate_per_s: float = Field(default=5.0, gt=0)
    ws_operator_burst: float = Field(default=20.0, ge=1)
    telemetry_retention_days: float = Field(default=90.0, gt=0)
    # commands reach an asset's socket on a broker nudge; this sweep catches a nudge that could not
    # arrive (several processes without REDIS_URL, a Redis hiccup)
    command_sweep_s: float = Field(default=20.0, gt=0)

    # autonomous runs: per-step time budgets in seconds, e.g. {"flying": 1800} (see server/runs/machine.py)
    run_timeouts: dict[str, float] = Field(default_factory=dict)
    run_engine: bool = True  # drive runs and fire schedules in this process (every replica may)
    schedule_grace_s: float = Field(
        default=60.0, ge=0, description="a due time later than this is 'missed'"
    )
    # the shortest `interval_s` a schedule may have; a flight every minute is already a lot, so
    # lower it only to exercise the scheduler (tests/deploy/test_schedule_replicas.py fires 20
    # due times 4 s apart on two replicas)
    schedule_min_interval_s: int = Field(default=60, ge=1, le=86400)

    # mission validation limits
    mission_min_alt_m: float = Field(default=2.0, ge=0)
    mission_max_alt_m: float = Field(default=120.0, gt=0)
    mission_max_area_m2: float = Field(default=4_000_000.0, gt=0)
    mission_max_items: int = Field(default=1000, ge=1)

    # failed-login rate limits
    login_window_s: int = Field(default=15 * 60, ge=1)
    login_max_failures_account: int = Field(default=5, ge=1)
    login_max_failures_address: int = Field(default=20, ge=1)
    # an address the account logged in from within this many days counts its failures apart
    login_known_client_days: float = Field(default=30, gt=0)

    # password hashing (argon2id); defaults are argon2-cffi's RFC 9106 low-memory profile
    argon2_time_cost: int = Field(default=3, ge=1)
    argon2_memory_kib: int = Field(default=65536, ge=8)
    argon2_parallelism: int = Field(default=4, ge=1)

    # scrypt for asset config files (log2 of N)
    config_scrypt_log_n: int = Field(default=15, ge=10, le=20)

    # live video (server/video, frontend_api.md "Live video"): the media path is the embedded
    # aiortc relay unless JANUS_URL is set; viewers per asset beyond video_max_viewers get 503
    video_path: Literal["embedded", "janus"] | None = None  # None: janus when JANUS_URL is set
    janus_url: str | None = Field(
        default=None, validation_alias=AliasChoices("JANUS_URL", "AEROBASE_JANUS_URL")
    )
    # the address assets send RTP to on the Janus path (default: JANUS_URL's host)
    janus_rtp_host: str | None = None
    video_max_viewers: int = Field(default=10, ge=1)
    video_retry_after_s: int = Field(default=5, ge=1)
    # ICE servers handed to viewers (and used by the relay), e.g. "stun:stun.example.com:3478";
    # TURN URLs get coturn `use-auth-secret` credentials valid for video_turn_ttl_s
    video_stun_urls: Annotated[list[str], NoDecode] = Field(default_factory=list)
    video_turn_urls: Annotated[list[str], NoDecode] = Field(default_factory=list)
    video_turn_secret: str | None = None
    video_turn_ttl_s: int = Field(default=3600, ge=60)
    # test and development only: ICE host candidates on 127.0.0.1 and nowhere else (aioice never
    # offers loopback), for everything on one machine (tests, the demo). Refused in production.
    video_ice_loopback: bool = False
    # recording (embedded path): each publication's frames as WebM segments, never re-encoded,
    # under <dir>/<asset id>/; off when unset; oldest deleted beyond the age or the total size
    video_record_dir: Path | None = None
    video_record_segment_s: float = Field(default=60.0, ge=1)
    video_record_max_age_days: float = Field(default=7.0, gt=0)
    video_record_max_bytes: int = Field(default=10 * 1024**3, ge=1024**2)

    @field_validator("video_stun_urls", "video_turn_urls", mode="before")
    @classmethod
    def _split_urls(cls, value: Any) -> Any:
        """A comma-separated list (the environment) or a list."""
        if isinstance(value, str):
            return [v for v in (part.strip() for part in value.split(",")) if v]
        return value

    @field_validator("cors_origins", mode="before")
    @classmethod
    def _split_origins(cls, value: Any) -> Any:
        """A comma-separated list (the environment) or a list; each origin without its slash."""
        if isinstance(value, str):
            value = [v for v in (part.strip() for part in value.split(",")) if v]
        if isinstance(value, list):
            return [v.rstrip("/") if isinstance(v, str) and v != "*" else v for v in value]
        return value

    @field_validator("map_tile_url")
    @classmethod
    def _tile_template(cls, value: str | None) -> str | None:
        """An http(s) URL or a same-origin path holding {z}, {x} and {y}; empty means none."""
        if not value:
            return None
        if not value.startswith(("https://", "http://", "/")) or value.startswith("//"):
            raise ValueError("map_tile_url must be an http(s):// URL or a path starting with /")
        missing = [k for k in ("{z}", "{x}", "{y}") if k not in value]
        if missing or any(c in value for c in '"<> '):
            raise ValueError(
                f"map_tile_url needs {{z}}, {{x}} and {{y}} and no quotes or spaces: {value!r}"
            )
        return value

    @model_validator(mode="after")
    def _check_production(self) -> Settings:
        if self.environment == "production" and self.database_url.startswith("sqlite"):
            # Allowed, but a production deployment should say it on purpose.
            pass
        if self.video_turn_urls and (self.video_turn_secret or "") in PLACEHOLDER_SECRETS:
            raise ValueError(
                "AEROBASE_VIDEO_TURN_URLS needs AEROBASE_VIDEO_TURN_SECRET (not a placeholder)"
            )
        if self.video_ice_loopback and self.environment == "production":
            raise ValueError("AEROBASE_VIDEO_ICE_LOOPBACK is for tests and development only")
        if self.environment == "production" and "*" in self.forwarded_allow_ips:
            raise ValueError(
                "FORWARDED_ALLOW_IPS must name the reverse proxy's address(es), not *: with * any "
                "client chooses the address the login limits and the audit log see"
            )
        if self.video_path == "janus" and not self.janus_url:
            raise ValueError("AEROBASE_VIDEO_PATH=janus needs JANUS_URL")
        return self

    @property
    def effective_video_path(self) -> Literal["embedded", "janus"]:
        """The media path: as set, else janus when JANUS_URL is set, else embedded."""
        if self.video_path is not None:
            return self.video_path
        return "janus" if self.janus_url else "embedded"

    @cached_property
    def effective_public_url(self) -> str:
        """The URL written into config files: explicit, else derived from host and port."""
        if self.public_url:
            return self.public_url.rstrip("/")
        host = "127.0.0.1" if self.host in ("0.0.0.0", "::") else self.host
        return f"http://{host}:{self.port}"

    def sqlite_path(self) -> Path | None:
        """The file of a SQLite database URL, so its folder can be created."""
        prefix = "sqlite+aiosqlite:///"
        if self.database_url.startswith(prefix):
            rest = self.database_url[len(prefix) :]
            return None if rest in ("", ":memory:") else Path(rest)
        return None
