"""The autopilot adapter: state, link supervision, commands that await their ACK, flight actions.

Usage::

    ap = Autopilot(AutopilotConfig(url="udpout:127.0.0.1:14550"))
    await ap.start()
    await ap.wait_link(10)
    await ap.upload_mission(items_from_dicts(server_items))   # verified by reading it back
    await ap.start_mission()                                  # GUIDED, arm, MISSION_START
    ap.state                                                  # the latest UavState
    await ap.close()

Commands send COMMAND_LONG, retry with an incremented confirmation on silence, and either
return or raise an `AutopilotError`.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import time
from collections.abc import Callable, Iterator
from dataclasses import replace
from functools import partial
from typing import Any

from asset_agent.autopilot import mission, translate
from asset_agent.autopilot.actions import ActionsMixin
from asset_agent.autopilot.boot import BootWatch
from asset_agent.autopilot.config import AutopilotConfig
from asset_agent.autopilot.errors import AutopilotTimeout, CommandRejected, LinkLost
from asset_agent.autopilot.fence import FenceMixin
from asset_agent.autopilot.flight_state import Thresholds, infer_landed_state
from asset_agent.autopilot.items import MissionItem
from asset_agent.autopilot.link import MavlinkLink
from asset_agent.autopilot.mission_watch import MissionWatch
from asset_agent.autopilot.setpoints import SetpointsMixin
from asset_agent.autopilot.state import Notification, UavState
from asset_agent.autopilot.streams import StreamKeeper, keep
from asynckit.roundtrips import RoundTrips
from asynckit.tasks import cancel_and_wait

log = logging.getLogger(__name__)

CMD_SET_MESSAGE_INTERVAL, CMD_REQUEST_MESSAGE = 511, 512
MAV_RESULT_ACCEPTED, MAV_RESULT_IN_PROGRESS = 0, 5


class Autopilot(ActionsMixin, SetpointsMixin, FenceMixin):
    """One autopilot over MAVLink, as seen from the companion computer."""

    def __init__(self, config: AutopilotConfig | None = None) -> None:
        self.config = config or AutopilotConfig()
        self.state = UavState()
        self._inbox: asyncio.Queue[Any] = asyncio.Queue()  # fed by the link's reader thread
        self._link = MavlinkLink(
            self.config.url,
            self._inbox,
            source_system=self.config.source_system,
            source_component=self.config.source_component,
        )
        self._link.on_reconnect = self._reconnected
        self._last_heartbeat: float | None = None
        self._taps: list[tuple[Callable[[Any], bool], asyncio.Queue[Any]]] = []
        self._subscribers: list[asyncio.Queue[Notification]] = []
        self._tasks: list[asyncio.Task[None]] = []
        self._command_lock = asyncio.Lock()
        self.mission_lock = asyncio.Lock()
        self._link_event = asyncio.Event()
        self.streams_requested = asyncio.Event()  # set once the stream requests have been sent
        self._rtcm_seq = 0
        self.statustexts: list[str] = []  # the latest 200
        self._texts_seen = 0  # every STATUSTEXT ever received, to tell which came after a command
        self.streams = StreamKeeper(self, self.config.streams)
        self._negotiation: asyncio.Task[None] | None = None
        self.mission_watch = MissionWatch()
        self.thresholds = Thresholds()
        self.extended_state_seen = False  # EXTENDED_SYS_STATE arrived: no landed-state inference
        self.boot = BootWatch()  # its reboots, from time_boot_ms (boot.py)
        self.reboots = 0
        self.unanswered_params: dict[str, int] = {}  # name -> `reboots` when it went unanswered
        self.round_trips = RoundTrips()  # COMMAND_LONG sent -> its final COMMAND_ACK

    # --- life cycle ------------------------------------------------------------------------
    async def start(self) -> None:
        """Open the link, start the heartbeat and the link watchdog; LinkLost if it cannot open."""
        try:
            await self._link.open()
        except (OSError, ValueError) as err:  # refused TCP, missing serial device, bad string
            raise LinkLost(f"cannot open {self.config.url}: {err}") from err
        self._send_heartbeat()
        self._tasks = [
            asyncio.create_task(self._dispatch(), name="autopilot-dispatch"),
            asyncio.create_task(self._heartbeat_loop(), name="autopilot-heartbeat"),
            asyncio.create_task(self._watchdog(), name="autopilot-watchdog"),
            asyncio.create_task(keep(self.streams), name="autopilot-stream-watchdog"),
        ]

    def spawn(self, coro: Any, name: str) -> None:
        """Run `coro` as a task the adapter cancels on close."""
        self._tasks = [t for t in self._tasks if not t.done()]
        self._tasks.append(asyncio.create_task(coro, name=name))

    async def close(self) -> None:
        """Stop every task and close the link."""
        await cancel_and_wait([*self._tasks, self._negotiation])
        await self._link.close()

    async def wait_link(self, within_s: float | None) -> None:
        """Wait until the autopilot's HEARTBEAT is seen (None: however long that takes);
        AutopilotTimeout otherwise."""
        try:
            await asyncio.wait_for(self._link_event.wait(), within_s)
        except TimeoutError as err:
            raise AutopilotTimeout(f"no HEARTBEAT from the autopilot within {within_s} s") from err

    @property
    def heartbeat_at(self) -> float | None:
        """When (time.monotonic()) the autopilot's last HEARTBEAT was handled, in the order the
        link delivered it: one handled after a COMMAND_ACK was sent after it."""
        return self._last_heartbeat

    @property
    def link_up(self) -> bool:
        """True while the autopilot's HEARTBEAT keeps arriving."""
        return self.state.link_up

    # --- incoming --------------------------------------------------------------------------
    async def _dispatch(self) -> None:
        while True:
            self._on_message(await self._inbox.get())

    def _on_message(self, msg: Any) -> None:
        """Apply one message from the autopilot: state, notifications, taps."""
        try:
            self._handle(msg)
        except Exception:  # a malformed message is logged, never kills the adapter
            log.exception("autopilot message %s not handled", msg.get_type())

    def _handle(self, msg: Any) -> None:
        # only the autopilot itself: a gimbal, camera or another companion on the same
        # system id must not overwrite its mode, armed state or mission progress
        if (msg.get_srcSystem(), msg.get_srcComponent()) != (
            self.config.target_system,
            self.config.target_component,
        ):
            return
        kind = msg.get_type()
        now = time.monotonic()
        self.streams.seen(msg.get_msgId(), now)
        if kind == "HEARTBEAT":
            self._last_heartbeat = now
            if not self.state.link_up:
                self._link_changed(True)
        self._check_reboot(getattr(msg, "time_boot_ms", None), now)
        prev = self.state
        cur = self._flight_state(prev, translate.apply(prev, msg), msg, now)
        reached = self.mission_watch.touched_down(prev, cur)
        if reached is not None:  # a final RTL / LAND item ends at touchdown: before `landed`
            self._notify(Notification("item_reached", index=reached))
        self.state = cur
        if kind == "STATUSTEXT":
            text = msg.text if isinstance(msg.text, str) else msg.text.decode(errors="replace")
            text = text.rstrip("\x00")
            self.statustexts.append(text)
            self._texts_seen += 1
            del self.statustexts[:-200]
            self._notify(Notification("statustext", text, msg.severity))
        elif kind == "MISSION_ITEM_REACHED":
            # only this mission's items, in turn: the last flight's, delivered late, are not
            state, ours = self.mission_watch.on_reached(self.state, msg.seq)
            if ours:
                self._notify(Notification("item_reached", index=msg.seq - 1))
            self.state = state
        for predicate, queue in list(self._taps):
            try:
                if predicate(msg):
                    queue.put_nowait(msg)
            except Exception:
                log.exception("message tap failed")

    def _flight_state(self, prev: UavState, cur: UavState, msg: Any, now: float) -> UavState:
        """Landed state and mission progress for autopilots that do not say them (flight_state.py)."""
        kind = msg.get_type()
        if kind == "EXTENDED_SYS_STATE":
            self.extended_state_seen = True
        elif kind == "MISSION_CURRENT" and getattr(msg, "mission_state", 0):
            self.mission_watch.reported = True
        if not self.extended_state_seen and kind in ("HEARTBEAT", "GLOBAL_POSITION_INT"):
            command = self.mission_watch.current_command()
            landed = infer_landed_state(prev.landed_state, cur, self.thresholds, command)
            cur = replace(cur, landed_state=landed)
        return self.mission_watch.on_change(prev, cur, now)

    def _check_reboot(self, boot_ms: int | None, now: float) -> None:
        """A reboot, told from late messages and slow clocks by `BootWatch` (boot.py): counted, the
        operator told, every stream asked for again."""
        why = None if boot_ms is None else self.boot.check(boot_ms, now)
        if why is None:
            return
        self.reboots += 1
        log.warning("the autopilot rebooted (%s)", why)
        self.extended_state_seen = False
        self._notify(Notification("statustext", "autopilot rebooted", 4))
        self._renegotiate()

    def _reconnected(self) -> None:
        """A new TCP connection is a new channel to the autopilot: ask for every stream again."""
        self._renegotiate()

    def _renegotiate(self) -> None:
        if self._negotiation is not None:
            self._negotiation.cancel()
        self._negotiation = asyncio.create_task(self.request_streams(), name="autopilot-streams")

    def _link_changed(self, up: bool) -> None:
        self.state = replace(self.state, link_up=up)
        if up:
            self._link_event.set()
            log.info("autopilot link up")
            self._notify(Notification("link_recovered"))
            self._renegotiate()
        else:
            self._link_event.clear()
            log.warning("autopilot link lost")
            self._notify(Notification("link_lost"))

    def _notify(self, note: Notification) -> None:
        note = replace(note, state=self.state)
        for q in self._subscribers:
            q.put_nowait(note)

    def subscribe(self) -> asyncio.Queue[Notification]:
        """A queue receiving every Notification from now on."""
        q: asyncio.Queue[Notification] = asyncio.Queue()
        self._subscribers.append(q)
        return q

    def unsubscribe(self, q: asyncio.Queue[Notification]) -> None:
        """Stop feeding a queue from `subscribe`."""
        if q in self._subscribers:
            self._subscribers.remove(q)

    @contextlib.contextmanager
    def tap(self, predicate: Callable[[Any], bool]) -> Iterator[asyncio.Queue[Any]]:
        """A queue of every incoming message matching `predicate`, while the block runs."""
        entry: tuple[Callable[[Any], bool], asyncio.Queue[Any]] = (predicate, asyncio.Queue())
        self._taps.append(entry)
        try:
            yield entry[1]
        finally:
            self._taps.remove(entry)

    async def _heartbeat_loop(self) -> None:
        while True:
            await asyncio.sleep(1.0)
            self._send_heartbeat()

    def _send_heartbeat(self) -> None:
        try:
            # MAV_TYPE_ONBOARD_CONTROLLER, MAV_AUTOPILOT_INVALID, MAV_STATE_ACTIVE
            self._link.send(lambda mav: mav.heartbeat_send(18, 8, 0, 0, 4))
        except Exception:
            log.warning("sending HEARTBEAT failed", exc_info=True)

    async def _watchdog(self) -> None:
        period = self.config.link_timeout_s / 10
        while True:
            await asyncio.sleep(period)
            last = self._last_heartbeat
            if self.state.link_up and last is not None:
                if time.monotonic() - last > self.config.link_timeout_s:
                    self._link_changed(False)

    # --- sending ---------------------------------------------------------------------------
    def send(self, build: Callable[[Any], Any]) -> None:
        """Send a raw message: `build(mav)` calls a pymavlink ``*_send`` method."""
        self._link.send(build)

    def require_link(self) -> None:
        """Raise LinkLost unless the autopilot link is up."""
        if not self.state.link_up:
            raise LinkLost("no HEARTBEAT from the autopilot")

    async def command(
        self,
        command: int,
        *params: float,
        ack_timeout_s: float | None = None,
        retries: int | None = None,
    ) -> int:
        """COMMAND_LONG awaiting its COMMAND_ACK; returns ACCEPTED or raises CommandRejected/AutopilotTimeout."""
        self.require_link()
        cfg = self.config
        timeout = cfg.command_timeout_s if ack_timeout_s is None else ack_timeout_s
        retries = cfg.command_retries if retries is None else retries
        p = [float(x) for x in params] + [0.0] * (7 - len(params))
        async with self._command_lock:
            mark = self._texts_seen
            with self.tap(lambda m: self._ack_for_us(m, command)) as acks:
                for confirmation in range(retries + 1):
                    self._link.send(partial(self._command_long, command, confirmation, p))
                    deadline = (sent_at := time.monotonic()) + timeout
                    while (left := deadline - time.monotonic()) > 0:
                        try:
                            ack = await asyncio.wait_for(acks.get(), left)
                        except TimeoutError:
                            break
                        if ack.result == MAV_RESULT_IN_PROGRESS:
                            deadline = time.monotonic() + timeout
                            continue
                        self.round_trips.observe(time.monotonic() - sent_at)
                        if ack.result != MAV_RESULT_ACCEPTED:
                            raise CommandRejected(command, ack.result, self._reason_since(mark))
                        return ack.result
                    if not self.state.link_up:
                        raise LinkLost(f"autopilot link lost while waiting for command {command}")
        raise AutopilotTimeout(f"no COMMAND_ACK for command {command} after {retries + 1} tries")

    def _ack_for_us(self, msg: Any, command: int) -> bool:
        """A COMMAND_ACK for `command` addressed to us (or to nobody in particular)."""
        if msg.get_type() != "COMMAND_ACK" or msg.command != command:
            return False
        target = getattr(msg, "target_system", 0)
        component = getattr(msg, "target_component", 0)
        cfg = self.config
        return target == 0 or (
            target == cfg.source_system and component in (0, cfg.source_component)
        )

    def _command_long(self, command: int, confirmation: int, p: list[float], mav: Any) -> None:
        cfg = self.config
        mav.command_long_send(cfg.target_system, cfg.target_component, command, confirmation, *p)

    def _reason_since(self, mark: int) -> str:
        """The autopilot's latest PreArm/failure text received after `mark`, to explain a rejection."""
        new = self.statustexts[
            len(self.statustexts) - min(self._texts_seen - mark, len(self.statustexts)) :
        ]
        for text in reversed(new):
            if text.startswith(("PreArm", "Arm", "Auto:", "Flight mode", "Plnd")):
                return text
        return ""

    async def request_streams(self) -> None:
        """Ask for every configured stream: SET_MESSAGE_INTERVAL, else REQUEST_DATA_STREAM (streams.py)."""
        self.streams_requested.clear()
        try:
            await self.streams.negotiate()
        except Exception:  # a failed negotiation leaves the watchdog to try again
            log.warning("stream negotiation failed", exc_info=True)
        self.streams_requested.set()

    def mission_uploaded(self, items: list[MissionItem], opaque_id: int = 0) -> None:
        """`items` are on the autopilot (its plan id `opaque_id`, 0 if none): mission progress
        starts afresh, and only this mission's start counts (mission_watch.py)."""
        self.mission_watch.uploaded(len(items), [item.command for item in items], opaque_id)
        self.state = replace(self.state, mission_total=len(items), mission_state="NOT_STARTED")

    async def set_message_interval(self, msg_id: int, hz: float) -> None:
        """MAV_CMD_SET_MESSAGE_INTERVAL: `hz` > 0 sets the rate, 0 stops the message."""
        interval_us = 1e6 / hz if hz > 0 else -1
        self.streams.want(msg_id, hz)  # the watchdog keeps the new rate, or leaves it stopped
        await self.command(CMD_SET_MESSAGE_INTERVAL, msg_id, interval_us)

    # --- missions (see mission.py) ---------------------------------------------------------
    async def upload_mission(
        self,
        items: list[MissionItem],
        verify: bool = True,
        progress: Callable[[str, int, int], None] | None = None,
    ) -> None:
        """Upload the mission (server list order, home added), then read it back and compare.

        `progress(phase, done, total)` reports "upload" then "verify" progress.
        """
        await mission.upload(self, items, verify=verify, progress=progress)

    async def download_mission(self) -> list[MissionItem]:
        """Read the mission back (home dropped)."""
        return await mission.download(self)

    async def adopt_mission(self) -> None:
        """Read the mission off the autopilot when this agent has uploaded none (it started after
        the upload: a restart, in flight perhaps), so that its progress and last item are known."""
        items = await self.download_mission()
        if self.mission_watch.total is None:  # an upload of this agent's came first: it stands
            commands = [item.command for item in items]
            self.mission_watch.uploaded(len(items), commands, adopted=True)
            self.state = replace(self.state, mission_total=len(items))
            log.info("the mission on the autopilot adopted: %d items", len(items))

    async def clear_mission(self) -> None:
        """MISSION_CLEAR_ALL, awaiting its MISSION_ACK."""
        await mission.clear(self)
