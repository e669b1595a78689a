"""How the agent reaches its autopilot and what it asks it to stream (`AutopilotConfig`)."""

from __future__ import annotations

from dataclasses import dataclass, field

# what the agent asks the autopilot to stream, message id -> Hz
DEFAULT_STREAMS: dict[int, float] = {
    1: 2.0,  # SYS_STATUS
    2: 1.0,  # SYSTEM_TIME: time_boot_ms tells a reboot
    24: 2.0,  # GPS_RAW_INT
    30: 5.0,  # ATTITUDE
    33: 5.0,  # GLOBAL_POSITION_INT
    42: 2.0,  # MISSION_CURRENT
    147: 1.0,  # BATTERY_STATUS
    242: 0.2,  # HOME_POSITION
    245: 2.0,  # EXTENDED_SYS_STATE
}


@dataclass(frozen=True)
class AutopilotConfig:
    """How to reach the autopilot and how patient to be with it."""

    url: str = "udpout:127.0.0.1:14550"
    target_system: int = 1
    target_component: int = 1
    source_system: int = 1
    source_component: int = 191  # MAV_COMP_ID_ONBOARD_COMPUTER
    link_timeout_s: float = 3.0  # no HEARTBEAT this long -> link lost
    command_timeout_s: float = 1.5
    command_retries: int = 3
    mission_timeout_s: float = 1.5  # per item, as MAVSDK and QGC use
    mission_retries: int = 4
    streams: dict[int, float] = field(default_factory=lambda: dict(DEFAULT_STREAMS))
