"""The ground side of the MAVLink mission protocol: upload, download, clear, with timeouts and retries.

Upload: MISSION_COUNT, then answer each MISSION_REQUEST_INT (or MISSION_REQUEST) with its
MISSION_ITEM_INT until the final MISSION_ACK. On silence the last message is re-sent, up to
`mission_retries` times per step, then MissionError(index, "timeout ..."). A MISSION_ACK with
an error ends the upload with MissionError naming the item being sent and the
MAV_MISSION_RESULT. Indices are the caller's (server list) indices: MAVLink seq - 1. The final MISSION_ACK's
opaque_id (ArduPilot 4.5+, PX4) names the plan; MISSION_CURRENT.mission_id then says whether
what the autopilot reports is of this plan (mission_watch.py).
"""

from __future__ import annotations

import asyncio
import logging
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

from asset_agent.autopilot import translate
from asset_agent.autopilot.errors import MissionError, mission_result_text
from asset_agent.autopilot.items import FRAME_GLOBAL, MissionItem
from asset_agent.autopilot.state import UavState
from asset_agent.autopilot.translate import OPAQUE_ID_OFFSET
from asset_agent.autopilot.verify import compare

if TYPE_CHECKING:
    from asset_agent.autopilot.client import Autopilot

log = logging.getLogger(__name__)

MAV_MISSION_ACCEPTED = 0
MAV_MISSION_TYPE_MISSION, MAV_MISSION_TYPE_FENCE, MAV_MISSION_TYPE_RALLY = 0, 1, 2
TYPE_NAMES = {0: "mission", 1: "fence", 2: "rally points"}
HOME_PLACEHOLDER = MissionItem(command=16, frame=FRAME_GLOBAL)


def home_item(state: UavState) -> MissionItem:
    """Item 0: the autopilot's home when known (as Mission Planner sends it), else zeros."""
    if state.home_lat is None or state.home_lon is None:
        return HOME_PLACEHOLDER
    return MissionItem(
        command=16,
        frame=FRAME_GLOBAL,
        x=round(state.home_lat * 1e7),
        y=round(state.home_lon * 1e7),
        z=state.home_alt_msl or 0.0,
    )


def _result_name(code: int) -> str:
    return mission_result_text(code)


def _index(seq: int | None) -> int | None:
    return None if seq is None or seq < 1 else seq - 1


def _fence_index(seq: int | None) -> int | None:
    return seq


def _index_of(mission: bool) -> Callable[[int | None], int | None]:
    """The caller's index of a seq: seq - 1 in a mission (seq 0 is home), seq otherwise."""
    return _index if mission else _fence_index


async def _await(ap: Autopilot, queue: asyncio.Queue[Any], step: str, index: int | None) -> Any:
    """One message from `queue` within the mission timeout, or None on silence."""
    try:
        return await asyncio.wait_for(queue.get(), ap.config.mission_timeout_s)
    except TimeoutError:
        if not ap.state.link_up:
            raise MissionError(index, f"autopilot link lost during {step}") from None
        return None


async def upload(
    ap: Autopilot,
    items: list[MissionItem],
    verify: bool = True,
    progress: Callable[[str, int, int], None] | None = None,
    mission_type: int = MAV_MISSION_TYPE_MISSION,
) -> None:
    """Upload `items` (home is prepended to a mission) and, with `verify`, read them back and
    compare. `mission_type` FENCE or RALLY sends a fence or rally points the same way: their
    lists have no home item (seq 0 is their first item), as ArduPilot's fence and rally
    protocols expect.

    `progress(phase, done, total)` is called as items go out ("upload") and come back ("verify").
    """
    ap.require_link()
    cfg = ap.config
    mission = mission_type == MAV_MISSION_TYPE_MISSION
    full = [home_item(ap.state), *items] if mission else list(items)
    kinds = ("MISSION_REQUEST_INT", "MISSION_REQUEST", "MISSION_ACK")
    idx = _index_of(mission)

    def send_count() -> None:
        ap.send(
            lambda mav: mav.mission_count_send(
                cfg.target_system, cfg.target_component, len(full), mission_type
            )
        )

    def send_item(seq: int) -> None:
        it = full[seq]
        ap.send(
            lambda mav: mav.mission_item_int_send(
                cfg.target_system, cfg.target_component, seq, it.frame, it.command,
                int(mission and seq == 0), it.autocontinue, it.param1, it.param2, it.param3,
                it.param4, it.x, it.y, it.z, mission_type,
            )
        )  # fmt: skip

    def ours(m: Any) -> bool:
        return m.get_type() in kinds and getattr(m, "mission_type", 0) == mission_type

    async with ap.mission_lock:
        with ap.tap(ours) as q:
            last_sent: int | None = None  # None: the count
            highest = -1
            opaque_id = 0
            send_count()
            tries = 0
            while True:
                msg = await _await(ap, q, "upload", idx(last_sent))
                if msg is None:
                    tries += 1
                    if tries > cfg.mission_retries:
                        where = "MISSION_COUNT" if last_sent is None else f"item seq {last_sent}"
                        raise MissionError(
                            idx(last_sent if last_sent is not None else highest + 1),
                            f"timeout: autopilot silent after {where}, {tries} tries",
                        )
                    log.info(
                        "mission upload: resending %s", "count" if last_sent is None else last_sent
                    )
                    if last_sent is None:
                        send_count()
                    else:
                        send_item(last_sent)
                    continue
                tries = 0
                if msg.get_type() == "MISSION_ACK":
                    if msg.type == MAV_MISSION_ACCEPTED and highest == len(full) - 1:
                        # the plan's id, where the autopilot gives one (mission_watch.py)
                        opaque_id = translate.extension_u32(msg, "opaque_id", OPAQUE_ID_OFFSET)
                        break
                    if msg.type == MAV_MISSION_ACCEPTED:
                        continue  # a stale ACK from an earlier transfer
                    bad = last_sent if last_sent is not None else None
                    raise MissionError(
                        idx(bad), f"rejected by the autopilot: {_result_name(msg.type)}"
                    )
                seq = msg.seq
                if not 0 <= seq < len(full):
                    raise MissionError(None, f"autopilot requested item seq {seq} of {len(full)}")
                send_item(seq)
                last_sent = seq
                if progress is not None and seq > highest and seq % 10 == 0:
                    progress("upload", seq, len(items))
                highest = max(highest, seq)
    log.info("%s uploaded: %d items", TYPE_NAMES.get(mission_type, "list"), len(items))
    if mission:
        ap.mission_uploaded(items, opaque_id)
    if progress is not None:
        progress("upload", len(items), len(items))
    if verify:
        back = await download(ap, progress, mission_type)
        if len(back) != len(items):
            raise MissionError(
                None,
                f"verification failed: sent {len(items)} {TYPE_NAMES.get(mission_type, '')} "
                f"items, read back {len(back)}",
            )
        for i, (sent, got) in enumerate(zip(items, back, strict=True)):
            mismatch = compare(sent, got)
            if mismatch is not None:
                raise MissionError(i, f"verification failed: {mismatch}")


async def download(
    ap: Autopilot,
    progress: Callable[[str, int, int], None] | None = None,
    mission_type: int = MAV_MISSION_TYPE_MISSION,
) -> list[MissionItem]:
    """Read the whole mission (MISSION_REQUEST_LIST, then each item); home is dropped.
    A fence or rally list (`mission_type`) has no home: every item is kept."""
    ap.require_link()
    cfg = ap.config
    async with ap.mission_lock:
        with ap.tap(
            lambda m: (
                m.get_type() == "MISSION_COUNT" and getattr(m, "mission_type", 0) == mission_type
            )
        ) as q:
            count = None
            for _ in range(cfg.mission_retries + 1):
                ap.send(
                    lambda mav: mav.mission_request_list_send(
                        cfg.target_system, cfg.target_component, mission_type
                    )
                )
                msg = await _await(ap, q, "download", None)
                if msg is not None:
                    count = msg.count
                    break
            if count is None:
                raise MissionError(None, "timeout: no MISSION_COUNT for MISSION_REQUEST_LIST")
        items: list[MissionItem] = []
        kinds = ("MISSION_ITEM_INT", "MISSION_ACK")
        with ap.tap(
            lambda m: m.get_type() in kinds and getattr(m, "mission_type", 0) == mission_type
        ) as q:
            for seq in range(count):
                items.append(await _download_item(ap, q, seq, mission_type))
                if progress is not None and (seq % 10 == 0 or seq == count - 1):
                    progress("verify", seq, count - 1)
        ap.send(
            lambda mav: mav.mission_ack_send(
                cfg.target_system, cfg.target_component, MAV_MISSION_ACCEPTED, mission_type
            )
        )
    return items[1:] if mission_type == MAV_MISSION_TYPE_MISSION else items


async def _download_item(
    ap: Autopilot, q: asyncio.Queue[Any], seq: int, mission_type: int = 0
) -> MissionItem:
    cfg = ap.config
    idx = _index_of(mission_type == MAV_MISSION_TYPE_MISSION)
    for _ in range(cfg.mission_retries + 1):
        ap.send(
            lambda mav: mav.mission_request_int_send(
                cfg.target_system, cfg.target_component, seq, mission_type
            )
        )
        while True:
            msg = await _await(ap, q, "download", idx(seq))
            if msg is None:
                break
            if msg.get_type() == "MISSION_ACK":
                raise MissionError(idx(seq), f"download refused: {_result_name(msg.type)}")
            if msg.seq == seq:
                return MissionItem(
                    msg.command, msg.frame, msg.param1, msg.param2, msg.param3, msg.param4,
                    msg.x, msg.y, msg.z, msg.autocontinue,
                )  # fmt: skip
    raise MissionError(idx(seq), f"timeout: no MISSION_ITEM_INT for seq {seq}")


async def clear(ap: Autopilot) -> None:
    """MISSION_CLEAR_ALL, retried until its MISSION_ACK."""
    ap.require_link()
    cfg = ap.config
    async with ap.mission_lock:
        with ap.tap(lambda m: m.get_type() == "MISSION_ACK") as q:
            for _ in range(cfg.mission_retries + 1):
                ap.send(
                    lambda mav: mav.mission_clear_all_send(
                        cfg.target_system, cfg.target_component, 0
                    )
                )
                msg = await _await(ap, q, "clear", None)
                if msg is None:
                    continue
                if msg.type != MAV_MISSION_ACCEPTED:
                    raise MissionError(None, f"clear refused: {_result_name(msg.type)}")
                return
    raise MissionError(None, "timeout: no MISSION_ACK for MISSION_CLEAR_ALL")
