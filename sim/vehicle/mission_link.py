"""The simulated autopilot's mission-protocol message handlers (upload, download, clear, set current)."""

from __future__ import annotations

from typing import Any

from pymavlink.dialects.v20 import ardupilotmega as mavlink

from sim.vehicle import mission as ms
from sim.vehicle.constants import AUTO, INFO
from sim.vehicle.fence import FenceMixin
from sim.vehicle.habits import stored
from sim.vehicle.mission_report import MissionAckWithId, mission_id, mission_total


class MissionProtocolMixin(FenceMixin):
    """MISSION_* handlers of `Copter`; state lives on the copter (items, upload, mission_current).

    Fence and rally lists (mission_type 1 and 2) go to `FenceMixin` (fence.py), which also keeps
    the fence parameters and enforces the fence."""

    items: list[ms.Item]
    mission_id: int  # the stored plan's opaque id (mission_report.py)
    faults: Any  # Faults: `stale_mission` replays the previous mission's end (stale.py)
    upload: ms.Upload | None
    upload_link: Any
    mission_current: int
    mode: int
    armed: bool
    wall: float
    config: Any
    guidance: Any

    def send(self, msg: Any, link: Any = None) -> None:
        """Queue a message (implemented by Copter)."""
        raise NotImplementedError

    def text(self, severity: int, text: str, throttle_s: float = 0.0) -> None:
        """Queue a STATUSTEXT (implemented by Copter)."""
        raise NotImplementedError

    def home_item(self) -> ms.Item:
        """Item 0 (implemented by Copter)."""
        raise NotImplementedError

    # --- mission protocol ------------------------------------------------------------------
    def _on_mission_count(self, msg: Any, link: Any) -> None:
        if getattr(msg, "mission_type", 0) != 0:
            self._typed_count(msg, link)  # fence or rally points (fence.py)
            return
        if (
            self.upload is not None
            and not self.upload.done
            and self.upload.count == msg.count
            and link is self.upload_link
        ):
            self._upload_action(self.upload.on_count_again(self.wall))
            return
        if self.upload is not None and not self.upload.done and link is not self.upload_link:
            # as ArduPilot: one upload at a time; another link is refused
            self.send(mavlink.MAVLink_mission_ack_message(255, 0, ms.DENIED), link)
            return
        cfg = self.config
        self.faults.stale_mission.upload_began(self)  # type: ignore[arg-type]
        self.upload = ms.Upload(msg.count, self.wall, cfg.mission_resend_s, cfg.mission_timeout_s)
        self.upload_link = link
        self._upload_action(self.upload.start())

    def _on_mission_item(self, msg: Any, link: Any) -> None:
        """The float MISSION_ITEM older ground stations send: same as the INT form."""
        msg.x, msg.y = round(msg.x * 1e7), round(msg.y * 1e7)
        self._on_mission_item_int(msg, link)

    def _on_mission_item_int(self, msg: Any, link: Any) -> None:
        if getattr(msg, "mission_type", 0) != 0:
            self._typed_item(msg, link)
            return
        if self.upload is None or self.upload.done or link is not self.upload_link:
            return
        item = ms.Item(
            msg.seq, msg.frame, msg.command, msg.param1, msg.param2, msg.param3, msg.param4,
            msg.x, msg.y, msg.z, msg.autocontinue,
        )  # fmt: skip
        action = self.upload.on_item(item, self.wall)
        if action:
            self._upload_action(action)

    def _upload_action(self, action: tuple[str, int]) -> None:
        kind, value = action
        if kind == "request":
            self.send(mavlink.MAVLink_mission_request_int_message(255, 0, value), self.upload_link)
            return
        if value == ms.ACCEPTED and self.upload is not None:
            items = self.upload.items[1:]
            if self.config.habits.ardupilot_storage:  # as AP_Mission packs them into storage
                items = [stored(it) for it in items]
            self.items = [self.home_item(), *items]
            self.mission_id = mission_id(self.items)
            self.mission_current = min(self.mission_current, len(self.items) - 1)
            self.faults.stale_mission.replay(self, "before_ack")  # type: ignore[arg-type]
            # 4.5+: the ack carries the new plan's id (MissionItemProtocol::send_mission_ack)
            ack = mavlink.MAVLink_mission_ack_message(255, 0, value)
            if self.config.habits.mission_ids:
                ack = MissionAckWithId(255, 0, value, self.mission_id)
            self.send(ack, self.upload_link)
            self.text(INFO, f"Flight plan received ({len(self.items)} items)")
            return
        self.send(mavlink.MAVLink_mission_ack_message(255, 0, value), self.upload_link)

    def _on_mission_request_list(self, msg: Any, link: Any) -> None:
        if getattr(msg, "mission_type", 0) != 0:
            self._typed_request_list(msg, link)
            return
        self.send(mavlink.MAVLink_mission_count_message(255, 0, len(self.items)), link)

    def _on_mission_request_int(self, msg: Any, link: Any) -> None:
        if getattr(msg, "mission_type", 0) != 0:
            self._typed_request(msg, link)
            return
        if not 0 <= msg.seq < len(self.items):
            self.send(mavlink.MAVLink_mission_ack_message(255, 0, ms.INVALID_SEQUENCE), link)
            return
        it = self.home_item() if msg.seq == 0 else self.items[msg.seq]
        self.send(
            mavlink.MAVLink_mission_item_int_message(
                255, 0, it.seq, it.frame, it.command, int(it.seq == self.mission_current),
                it.autocontinue, it.param1, it.param2, it.param3, it.param4, it.x, it.y, it.z,
            ),
            link,
        )  # fmt: skip

    _on_mission_request = _on_mission_request_int

    def _on_mission_ack(self, msg: Any, link: Any) -> None:
        """The ground's ack closing a download: nothing to do."""

    def _on_mission_clear_all(self, msg: Any, link: Any) -> None:
        if getattr(msg, "mission_type", 0) != 0:
            self._typed_clear(msg, link)
            return
        self.items = [self.home_item()]
        self.mission_id = 0
        self.mission_current = 0
        self.guidance.mission_cleared()
        self.send(mavlink.MAVLink_mission_ack_message(255, 0, ms.ACCEPTED), link)

    def _on_mission_set_current(self, msg: Any, link: Any) -> None:
        if 0 < msg.seq < len(self.items):
            self.mission_current = msg.seq
            if self.mode == AUTO and self.armed:
                self.guidance.start_item(msg.seq)
        self.send(
            mavlink.MAVLink_mission_current_message(
                self.mission_current, mission_total(self.items)
            ),
            link,
        )
