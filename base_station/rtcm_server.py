"""The base's RTCM3 stream on the site's own network: a plain TCP corrections server.

Every client that connects receives the reference receiver's checked RTCM3 frames as a raw byte
stream from then on, nothing to send first: the format of a receiver's own stream port and of
RTKLIB's `tcpsvr://`, so the UAV's agent (`[rtk] local_source = "tcp://base:2102"`) and any
other rover on the site read it. It is the corrections' path that does not pass through the
server: with the server down the UAV keeps its RTK fixed fix. Off unless `[rtk] serve_port` is
set. A slow client loses its oldest frames (`RtkReader.frames`), never stalls the others.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging

from assetlink.rtk import RtkReader
from asynckit.tasks import cancel_and_wait

log = logging.getLogger(__name__)


class RtcmServer:
    """Serves `reader`'s frames to every TCP client on (host, port)."""

    def __init__(self, reader: RtkReader, host: str, port: int) -> None:
        self.reader = reader
        self.host, self.port = host, port
        self.clients = 0
        self._server: asyncio.Server | None = None
        self._tasks: set[asyncio.Task[None]] = set()

    async def start(self) -> int:
        """Bind and serve; returns the bound port."""
        self._server = await asyncio.start_server(self._serve, self.host, self.port)
        self.port = self._server.sockets[0].getsockname()[1]
        log.info("rtcm: serving the base's corrections on %s:%d", self.host, self.port)
        return self.port

    async def close(self) -> None:
        """Stop serving and drop every client."""
        if self._server is not None:
            self._server.close()
        await cancel_and_wait(list(self._tasks))
        if self._server is not None:
            await self._server.wait_closed()

    async def _serve(self, _reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        task = asyncio.current_task()
        assert task is not None  # start_server runs each connection as a task
        self._tasks.add(task)
        self.clients += 1
        peer = writer.get_extra_info("peername")
        log.info("rtcm: client %s", peer)
        frames = self.reader.frames()
        try:
            async for frame in frames:
                writer.write(frame)
                await writer.drain()
        except (ConnectionError, OSError) as err:
            log.info("rtcm: client %s gone (%s)", peer, err)
        finally:
            await frames.aclose()
            self.clients -= 1
            self._tasks.discard(task)
            writer.close()
            with contextlib.suppress(ConnectionError, OSError):
                await writer.wait_closed()
