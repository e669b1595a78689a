"""Telling an asset's followers when its live video starts or stops: `video_state` on /ws/operator.

A page that shows many UAVs' video (the console's fleet) opens a viewer session only for a UAV
that is live and learns of the others' start from this message, instead of holding a session per
idle UAV or asking each one's description again and again. The message goes through the broker on
the asset's channel, so it reaches the asset's followers in every replica.

The state sent is what the media path says at that moment (`GET .../video`'s `state`), not what
the change implies: a publication replaced by the next one says `live` however the two ends race.
On the Janus path the stream is live once the mountpoint has had media, a moment after the asset
has asked where to send it; the announcement waits for that, for at most `until_live_s`, and is
sent only if the stream was not live already when the asset asked (the agent asks again every few
seconds while it streams: nothing has changed then) and has become live by the end. One wait per
asset: an asset that asks again before its media has arrived extends the wait under way rather
than starting a second one, which would tell its followers `live` twice.
"""

from __future__ import annotations

import asyncio
import logging
import uuid

from protocol.messages import VideoStatePayload, envelope
from server.realtime.broker import Broker
from server.realtime.channels import asset_channel
from server.video.gateway import MediaGateway

log = logging.getLogger(__name__)
POLL_S = 0.5  # the Janus path: how often to look whether the media has arrived
_running: set[asyncio.Task[None]] = set()  # announcements under way (a task needs a reference)
_awaited: dict[uuid.UUID, float] = {}  # the Janus path: assets whose media is awaited, until when


def announce(
    broker: Broker,
    gateway: MediaGateway,
    asset_id: uuid.UUID,
    until_live_s: float = 0.0,
) -> None:
    """Send the asset's video state to its followers, soon (never blocks, never raises); with
    `until_live_s`, only its becoming live within that long (nothing if it already was)."""
    task = asyncio.get_running_loop().create_task(
        _announce(broker, gateway, asset_id, until_live_s)
    )
    _running.add(task)
    task.add_done_callback(_running.discard)


async def _announce(
    broker: Broker, gateway: MediaGateway, asset_id: uuid.UUID, until_live_s: float
) -> None:
    try:
        if until_live_s > 0:
            if not await _becomes_live(gateway, asset_id, until_live_s):
                return
            live = True
        else:
            live = (await gateway.status(asset_id)).live
        message = envelope(
            VideoStatePayload(asset_id=asset_id, state="live" if live else "offline")
        ).model_dump(mode="json")
        await broker.publish(asset_channel(asset_id), message)
    except Exception as err:  # the gateway or the broker away: pages find out when they look
        log.warning("could not announce asset %s's video state: %r", asset_id, err)


async def _becomes_live(gateway: MediaGateway, asset_id: uuid.UUID, within_s: float) -> bool:
    """True when the asset's stream, offline as it asked, gets media within `within_s`. False
    when it was live already (nothing changed), stays offline, or is awaited by an earlier ask
    (whose wait this one extends: that one tells)."""
    loop = asyncio.get_running_loop()
    deadline = loop.time() + within_s
    if asset_id in _awaited:
        _awaited[asset_id] = max(_awaited[asset_id], deadline)
        return False
    _awaited[asset_id] = deadline
    try:
        if (await gateway.status(asset_id)).live:
            return False
        while loop.time() < _awaited[asset_id]:
            await asyncio.sleep(POLL_S)
            if (await gateway.status(asset_id)).live:
                return True
        return False
    finally:
        del _awaited[asset_id]
