"""What the simulated autopilot says about its mission: MISSION_CURRENT and the plan's id.

`mission_id` follows ArduPilot 4.5+ (libraries/GCS_MAVLink/MissionItemProtocol.cpp,
`update_checksum` / `opaque_id`): a CRC32 over each stored item's frame, command, autocontinue,
param1-4, x, y and z, 0 replaced by UINT32_MAX (0 means "no id" in the extension field). The
id is of the content, not of the upload: the same items uploaded again get the same id, so the
id tells another plan from this one, never this flight from the last flight of the same plan.
ArduPilot defers the upload's MISSION_ACK until the sum is ready (it starts 500 ms after the
last change); the simulator sums at once and does not model that delay. PX4 streams a CRC32
of its mission the same way (src/modules/mavlink/mavlink_mission.cpp, MISSION_CURRENT.mission_id
and MISSION_ACK.opaque_id).

pymavlink 2.4.50's generated dialects stop before these extension fields (common.xml added them
in 2023): `MissionCurrentWithIds` and `MissionAckWithId` pack them after the fields it knows. The
CRC_EXTRA does not cover extensions, so any MAVLink 2 peer reads the message; one that does not
know the fields drops the bytes, as MAVLink 2 intends.
"""

from __future__ import annotations

import struct
import zlib
from typing import TYPE_CHECKING, Any

from pymavlink.dialects.v20 import ardupilotmega as mavlink

from sim.vehicle import mission as ms
from sim.vehicle.constants import AUTO

if TYPE_CHECKING:
    from sim.vehicle.copter import Copter

UINT32_MAX = 0xFFFFFFFF


class MissionCurrentWithIds(mavlink.MAVLink_mission_current_message):
    """MISSION_CURRENT with its mission_id, fence_id and rally_points_id extensions."""

    def __init__(self, seq: int, total: int, state: int, mode: int, ids: tuple[int, int, int]):
        super().__init__(seq, total, state, mode)
        self.mission_id, self.fence_id, self.rally_points_id = ids

    def pack(self, mav: Any, force_mavlink1: bool = False) -> bytes:
        """The known fields, then the three ids (uint32 each, in the message's order)."""
        known = self.unpacker.pack(self.seq, self.total, self.mission_state, self.mission_mode)
        ids = struct.pack("<III", self.mission_id, self.fence_id, self.rally_points_id)
        return bytes(self._pack(mav, self.crc_extra, known + ids, force_mavlink1=force_mavlink1))


class MissionAckWithId(mavlink.MAVLink_mission_ack_message):
    """MISSION_ACK with its opaque_id extension: the id of the plan an upload left."""

    def __init__(self, target_system: int, target_component: int, result: int, opaque_id: int):
        super().__init__(target_system, target_component, result, 0)
        self.opaque_id = opaque_id

    def pack(self, mav: Any, force_mavlink1: bool = False) -> bytes:
        """The known fields, then opaque_id (uint32)."""
        known = self.unpacker.pack(
            self.target_system, self.target_component, self.type, self.mission_type
        )
        payload = known + struct.pack("<I", self.opaque_id)
        return bytes(self._pack(mav, self.crc_extra, payload, force_mavlink1=force_mavlink1))


def mission_total(items: list[ms.Item]) -> int:
    """MISSION_CURRENT.total: items without home (the last seq), UINT16_MAX when there are none."""
    return len(items) - 1 if len(items) > 1 else 0xFFFF


def mission_id(items: list[ms.Item]) -> int:
    """The plan's opaque id: a CRC32 of the stored items from ArduPilot's
    `opaque_id_first_item()`, here the first after home (home moves with every arming, the plan
    does not); 0 for no mission."""
    if len(items) <= 1:
        return 0
    crc = 0
    for it in items[1:]:
        packed = struct.pack(
            "<BHBffffiif", it.frame, it.command, it.autocontinue, it.param1, it.param2,
            it.param3, it.param4, it.x, it.y, it.z,
        )  # fmt: skip
        crc = zlib.crc32(packed, crc)
    return crc or UINT32_MAX


def mission_current_message(c: Copter) -> Any:
    """MISSION_CURRENT as the habits send it: seq only (before 4.4), with total, mission_state
    and mission_mode (4.4), and the plan's id (4.5+)."""
    habits = c.config.habits
    if not habits.mission_current_extensions:
        return mavlink.MAVLink_mission_current_message(c.mission_current)
    fields = (
        c.mission_current,
        mission_total(c.items),
        c.guidance.reported_mission_state(),
        int(c.mode == AUTO),
    )
    if not habits.mission_ids:
        return mavlink.MAVLink_mission_current_message(*fields)
    # the fence and rally lists have ids of their own in ArduPilot; the simulator sends none
    return MissionCurrentWithIds(*fields, (c.mission_id, 0, 0))
