"""Fire-and-forget messages to the autopilot: RTK corrections, landing targets, guided setpoints."""

from __future__ import annotations

import logging
import time
from collections.abc import Callable
from functools import partial
from typing import Any

from protocol.rtcm import MAVLINK_MAX_MESSAGE, mavlink_fragments

log = logging.getLogger(__name__)

# SET_POSITION_TARGET_LOCAL_NED type_mask: a velocity only (ignore position, acceleration, yaw,
# yaw rate)
VELOCITY_ONLY = 0b0000_1101_1100_0111


def _rtcm(flags: int, length: int, data: bytes, mav: Any) -> None:
    mav.gps_rtcm_data_send(flags, length, data)


class SetpointsMixin:
    """Senders that need no answer; the host class provides `config` and `send`."""

    config: Any
    _rtcm_seq: int = 0

    def send(self, build: Callable[[Any], Any]) -> None:
        """Send a raw message (implemented by the host class)."""
        raise NotImplementedError

    def inject_rtcm(self, frame: bytes) -> int:
        """Send RTCM3 bytes (normally one frame) as GPS_RTCM_DATA fragments; the fragment count.

        Up to 719 bytes go as one message (fragmented per the MAVLink rules); longer input is
        cut into 719-byte messages sent in order, which the autopilot passes on to its GNSS
        receiver as one byte stream. A failed send is logged and counted as 0: corrections
        are a stream, one lost frame is not an error.
        """
        try:
            data = bytes(frame)
        except TypeError as err:
            log.warning("RTCM data not injected: %s", err)
            return 0
        size = MAVLINK_MAX_MESSAGE - 1
        sent = 0
        try:
            for start in range(0, len(data), size):
                fragments = mavlink_fragments(data[start : start + size], self._rtcm_seq)
                self._rtcm_seq = (self._rtcm_seq + 1) % 32
                for flags, chunk in fragments:
                    padded = chunk + bytes(180 - len(chunk))
                    self.send(partial(_rtcm, flags, len(chunk), padded))
                    sent += 1
        except ConnectionError as err:  # the link is reconnecting: corrections resume after
            log.info("RTCM data not injected: %s", err)
        except (OSError, RuntimeError) as err:
            log.warning("RTCM data not injected: %s", err)
        return sent

    def send_landing_target(
        self,
        angle_x: float,
        angle_y: float,
        distance: float = 0.0,
        frame: int = 12,
        position: tuple[float, float, float] | None = None,
    ) -> None:
        """LANDING_TARGET (default MAV_FRAME_BODY_FRD); `position` sets position_valid."""
        x, y, z = position or (0.0, 0.0, 0.0)
        usec = int(time.time() * 1e6)
        self.send(
            lambda mav: mav.landing_target_send(
                usec, 0, frame, angle_x, angle_y, distance, 0, 0, x, y, z, [1, 0, 0, 0], 2,
                int(position is not None),
            )
        )  # fmt: skip

    def send_velocity_ned(self, vn: float, ve: float, vd: float) -> None:
        """SET_POSITION_TARGET_LOCAL_NED with a velocity only (GUIDED)."""
        cfg = self.config
        self.send(
            lambda mav: mav.set_position_target_local_ned_send(
                0,
                cfg.target_system,
                cfg.target_component,
                1,
                VELOCITY_ONLY,
                0,
                0,
                0,
                vn,
                ve,
                vd,
                0,
                0,
                0,
                0,
                0,
            )
        )

    def send_position_ned(self, n: float, e: float, d: float) -> None:
        """SET_POSITION_TARGET_LOCAL_NED with a position from home (GUIDED)."""
        cfg = self.config
        mask = 0b0000_1101_1111_1000  # ignore velocity, acceleration, yaw, yaw rate
        self.send(
            lambda mav: mav.set_position_target_local_ned_send(
                0, cfg.target_system, cfg.target_component, 1, mask, n, e, d, 0, 0, 0, 0, 0, 0, 0, 0
            )
        )
