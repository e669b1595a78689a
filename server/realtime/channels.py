"""Names of the broker's channels and presence keys: the one place they are spelt.

  `asset.<id>`        what an asset sent (telemetry, event, command_result, run progress), for operators
  `cmd.<id>`          a nudge: commands are waiting for this asset (delivered from the database)
  `rtcm.<id>`         RTCM3 corrections a landing base publishes, for its UAVs and the NTRIP caster
  `sessions.ended`    {"ids": [...]}: close those sessions' sockets (code 4001)
Presence key `conn.asset.<id>`: one live connection per asset across every process.
Slot keys `ws.session.<id>.<n>`: an operator socket holds one of its login session's n slots.
"""

from __future__ import annotations

import uuid


def asset_channel(asset_id: uuid.UUID) -> str:
    """What an asset sent, fanned out to the operators watching it."""
    return f"asset.{asset_id}"


def command_channel(asset_id: uuid.UUID) -> str:
    """Nudges that commands wait for this asset."""
    return f"cmd.{asset_id}"


def rtcm_channel(base_id: uuid.UUID) -> str:
    """RTCM3 corrections of a landing base."""
    return f"rtcm.{base_id}"


def sessions_ended_channel() -> str:
    """Ids of ended sessions whose sockets every process closes."""
    return "sessions.ended"


def presence_key(asset_id: uuid.UUID) -> str:
    """The presence claim of an asset's one live connection."""
    return f"conn.asset.{asset_id}"


def socket_slot_key(session_id: uuid.UUID, index: int) -> str:
    """Slot `index` of a login session's operator sockets (claimed like a presence)."""
    return f"ws.session.{session_id}.{index}"
