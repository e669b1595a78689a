"""Getting the telemetry streams out of any ArduPilot or PX4 release, and keeping them coming.

Negotiation (on every link-up and every autopilot reboot):
1. MAV_CMD_SET_MESSAGE_INTERVAL for the first stream, answered within `PROBE_TIMEOUT_S` x 2 tries;
   ACCEPTED: every stream is asked for the same way (ArduPilot 4.x, PX4), and home once by
   MAV_CMD_GET_HOME_POSITION too (ArduPilot sends a message first one interval after it is
   asked for: home at 0.2 Hz would come 5 s after the link);
2. UNSUPPORTED, DENIED or no answer (ArduPilot 3.x answers UNSUPPORTED): REQUEST_DATA_STREAM for
   the ArduCopter stream groups holding the wanted messages (`GROUPS`, from ArduCopter's
   GCS_Mavlink.cpp STREAM_*_msgs), each at the highest rate wanted in it (whole Hz, at least 1);
   HOME_POSITION, which is in no group, with MAV_CMD_GET_HOME_POSITION;
3. a message refused alone (FAILED) falls back to its group the same way.

Watchdog: a wanted message silent for `SILENT_PERIODS` periods (at least `MIN_SILENCE_S`) is
asked for again, the way negotiation found to work, then again after twice as long each time
(at most `MAX_BACKOFF_S`), so a message an autopilot never sends (EXTENDED_SYS_STATE on 3.x)
costs one request every 30 s.
"""

from __future__ import annotations

import asyncio
import logging
import math
import time
from functools import partial
from typing import TYPE_CHECKING, Any, Literal

from asset_agent.autopilot.errors import AutopilotError, AutopilotTimeout, CommandRejected

if TYPE_CHECKING:
    from asset_agent.autopilot.client import Autopilot

log = logging.getLogger(__name__)

CMD_SET_MESSAGE_INTERVAL, CMD_GET_HOME_POSITION = 511, 410
MAV_RESULT_DENIED, MAV_RESULT_UNSUPPORTED = 2, 3
HOME_POSITION = 242
# message id -> MAV_DATA_STREAM group (ArduCopter GCS_Mavlink.cpp)
GROUPS: dict[int, int] = {
    1: 2,  # SYS_STATUS: EXTENDED_STATUS
    24: 2,  # GPS_RAW_INT: EXTENDED_STATUS
    42: 2,  # MISSION_CURRENT: EXTENDED_STATUS
    33: 6,  # GLOBAL_POSITION_INT: POSITION
    32: 6,  # LOCAL_POSITION_NED: POSITION
    30: 10,  # ATTITUDE: EXTRA1
    74: 11,  # VFR_HUD: EXTRA2
    2: 12,  # SYSTEM_TIME: EXTRA3
    147: 12,  # BATTERY_STATUS: EXTRA3
}
PROBE_TIMEOUT_S = 1.0
SILENT_PERIODS = 3.0
MIN_SILENCE_S = 2.0
MAX_BACKOFF_S = 30.0

Method = Literal["interval", "data_stream"]


def _data_stream(system: int, component: int, group: int, hz: int, mav: Any) -> None:
    mav.request_data_stream_send(system, component, group, hz, 1)


class StreamKeeper:
    """Asks the autopilot for `wanted` (message id -> Hz) and keeps every stream alive."""

    def __init__(self, ap: Autopilot, wanted: dict[int, float]) -> None:
        self.ap = ap
        self.wanted = {k: v for k, v in wanted.items() if v > 0}
        self.stopped = {k for k, v in wanted.items() if v <= 0}
        self.method: Method | None = None
        self.by_group: set[int] = set()  # messages that go by REQUEST_DATA_STREAM
        self.last_seen: dict[int, float] = {}
        self._asked: dict[int, float] = {}  # message id -> when last asked
        self._backoff: dict[int, float] = {}
        self.negotiations = 0

    def want(self, msg_id: int, hz: float) -> None:
        """Change one wanted rate (0 or less: stopped, no longer watched)."""
        if hz > 0:
            self.wanted[msg_id] = hz
            self.stopped.discard(msg_id)
        else:
            self.wanted.pop(msg_id, None)
            self.stopped.add(msg_id)

    def seen(self, msg_id: int, now: float | None = None) -> None:
        """A message arrived."""
        self.last_seen[msg_id] = time.monotonic() if now is None else now

    async def negotiate(self) -> None:
        """Find how this autopilot takes stream requests and ask for everything."""
        self.negotiations += 1
        self.method = None
        self.by_group = set()
        self._backoff.clear()
        for msg_id, hz in self.wanted.items():
            if self.method == "data_stream":
                self.by_group.add(msg_id)
                continue
            answer = await self._try_interval(msg_id, hz)
            if answer == "ok":
                self.method = "interval"
            elif answer == "refused" and self.method is None:
                log.info("SET_MESSAGE_INTERVAL not supported: falling back to REQUEST_DATA_STREAM")
                self.method = "data_stream"
                self.by_group.add(msg_id)
            else:  # this one message refused, or silence on a link that took others
                self.by_group.add(msg_id)
        self._request_groups(self.by_group)
        if HOME_POSITION in self.wanted and HOME_POSITION not in self.by_group:
            # by interval its first comes one interval later (ArduPilot's new message bucket
            # waits that long: 5 s at 0.2 Hz), and an agent waits for home: asked once now too
            self.ap.spawn(self._ask_home(), "autopilot-home")
        if self.method == "interval":  # best effort, last: streams asked off
            for msg_id in self.stopped:
                await self._try_interval(msg_id, -1.0)
        now = time.monotonic()
        for msg_id in self.wanted:
            self._asked[msg_id] = now

    async def _try_interval(self, msg_id: int, hz: float) -> str:
        """ "ok", "refused" (UNSUPPORTED / DENIED / silence) or "failed" (this message only)."""
        interval_us = 1e6 / hz if hz > 0 else -1
        try:
            await self.ap.command(
                CMD_SET_MESSAGE_INTERVAL,
                msg_id,
                interval_us,
                ack_timeout_s=PROBE_TIMEOUT_S,
                retries=1,
            )
        except CommandRejected as err:
            if err.result in (MAV_RESULT_UNSUPPORTED, MAV_RESULT_DENIED):
                return "refused"
            log.info("stream %s refused: %s", msg_id, err)
            return "failed"
        except AutopilotTimeout:
            return "refused" if self.method is None else "failed"
        except AutopilotError as err:
            log.info("stream %s not set: %s", msg_id, err)
            return "failed"
        return "ok"

    def _request_groups(self, msg_ids: set[int]) -> None:
        """REQUEST_DATA_STREAM for the groups holding `msg_ids`; home by GET_HOME_POSITION."""
        rates: dict[int, int] = {}
        for msg_id in msg_ids:
            group = GROUPS.get(msg_id)
            if group is not None:
                rates[group] = max(rates.get(group, 1), math.ceil(self.wanted[msg_id]))
        cfg = self.ap.config
        for group, hz in sorted(rates.items()):
            self.ap.send(partial(_data_stream, cfg.target_system, cfg.target_component, group, hz))
        if HOME_POSITION in msg_ids:
            self.ap.spawn(self._ask_home(), "autopilot-home")
        log.info("asked for stream groups %s", rates)

    async def _ask_home(self) -> None:
        try:
            await self.ap.command(CMD_GET_HOME_POSITION, ack_timeout_s=PROBE_TIMEOUT_S, retries=1)
        except AutopilotError as err:
            log.info("GET_HOME_POSITION: %s", err)

    def silent(self, now: float) -> list[int]:
        """Wanted messages silent for too long whose next request is due."""
        out = []
        for msg_id, hz in self.wanted.items():
            limit = max(SILENT_PERIODS / hz, MIN_SILENCE_S)
            asked = self._asked.get(msg_id, now)
            heard = max(self.last_seen.get(msg_id, -math.inf), asked)
            wait = self._backoff.get(msg_id, limit)
            if now - heard > limit and now - asked > wait:
                out.append(msg_id)
        return out

    async def watch(self, now: float | None = None) -> list[int]:
        """One watchdog pass: ask again for every silent stream; the ids asked for."""
        if self.method is None:
            return []
        now = time.monotonic() if now is None else now
        due = self.silent(now)
        if not due:
            return []
        regroup = {m for m in due if m in self.by_group}
        for msg_id in due:
            self._asked[msg_id] = now
            limit = max(SILENT_PERIODS / self.wanted[msg_id], MIN_SILENCE_S)
            self._backoff[msg_id] = min(self._backoff.get(msg_id, limit) * 2, MAX_BACKOFF_S)
            if (
                msg_id not in regroup
                and await self._try_interval(msg_id, self.wanted[msg_id]) != "ok"
            ):
                regroup.add(msg_id)
        if regroup:
            self._request_groups(regroup)
        log.info("re-requested silent streams %s", due)
        return due


async def keep(keeper: StreamKeeper, period_s: float = 0.5) -> None:
    """Run the watchdog forever."""
    while True:
        await asyncio.sleep(period_s)
        try:
            await keeper.watch()
        except (AutopilotError, OSError) as err:  # link down or reconnecting: next pass
            log.info("stream watchdog: %s", err)
        except Exception:  # never let the watchdog die
            log.exception("stream watchdog pass failed")
