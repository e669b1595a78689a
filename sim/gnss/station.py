"""The simulated base receiver's configuration and its pure epoch -> RTCM3 frames function."""

from __future__ import annotations

import math
from functools import cached_property
from typing import Literal

from pydantic import BaseModel, ConfigDict, Field

from protocol.rtcm import build_frame
from sim.gnss.messages import encode_1005, encode_1230, encode_msm
from sim.gnss.sky import GALILEO, GPS, GPS_WEEK_MS, Sky, geodetic_to_ecef


class GnssConfig(BaseModel):
    """What the simulated base receiver is and sends (all deterministic from `seed`)."""

    model_config = ConfigDict(frozen=True)

    station_id: int = Field(default=1, ge=0, le=4095)
    latitude: float = Field(default=41.1780, ge=-90, le=90)
    longitude: float = Field(default=-8.5980, ge=-180, le=180)
    height_m: float = 120.0
    seed: int = 0
    msm: Literal[4, 7] = 7
    gps_satellites: int = Field(default=9, ge=1, le=16)
    galileo_satellites: int = Field(default=8, ge=1, le=16)
    reference_every: int = Field(default=1, ge=1, description="send 1005 and 1230 every N epochs")
    start_tow_ms: int = Field(default=345_600_000, ge=0, lt=GPS_WEEK_MS)
    glonass_biases_m: tuple[float | None, float | None, float | None, float | None] = (
        -71.94,
        None,
        -71.94,
        None,
    )


class BaseStationModel:
    """Turns an epoch index (one per simulated second) into that epoch's clean RTCM3 frames."""

    def __init__(self, config: GnssConfig) -> None:
        self.config = config
        self.ecef = geodetic_to_ecef(config.latitude, config.longitude, config.height_m)
        self.gps = Sky(GPS, config.seed, config.gps_satellites)
        self.galileo = Sky(GALILEO, config.seed, config.galileo_satellites)

    @cached_property
    def message_types(self) -> tuple[int, ...]:
        """Message numbers this station sends, in stream order."""
        m = self.config.msm
        return (1005, GPS.msm_base + m, GALILEO.msm_base + m, 1230)

    def tow_ms(self, epoch: int) -> int:
        """GPS (and Galileo) time of week of epoch `epoch`, in milliseconds."""
        return (self.config.start_tow_ms + epoch * 1000) % GPS_WEEK_MS

    def frames(self, epoch: int) -> list[bytes]:
        """The complete RTCM3 frames of epoch `epoch` (>= 0), CRC included, in stream order."""
        cfg = self.config
        reference = epoch % cfg.reference_every == 0
        tow = self.tow_ms(epoch)
        lock_ms = epoch * 1000 + 500  # tracked since the receiver started
        out = []
        if reference:
            out.append(build_frame(encode_1005(cfg.station_id, self.ecef)))
        for sky, last in ((self.gps, False), (self.galileo, True)):
            sats = sky.observe(float(epoch), lock_ms)
            number = sky.constellation.msm_base + cfg.msm
            payload = encode_msm(number, cfg.station_id, tow, sats, multiple_message=not last)
            out.append(build_frame(payload))
        if reference:
            out.append(build_frame(encode_1230(cfg.station_id, cfg.glonass_biases_m)))
        return out

    def bitrate(self) -> int:
        """Approximate stream bitrate in bit/s (for a sourcetable entry)."""
        return math.ceil(sum(len(f) for f in self.frames(0)) * 8)
