"""RTK corrections into the autopilot, from the base on the site's network first, the server second.

Two paths carry the base's RTCM3 frames: the base's own corrections stream on the site's network
(`[rtk] local_source`, base_station/rtcm_server.py; read by `assetlink.rtk.RtkReader`), which
keeps working with the server down, and the server's relay over the link (`Link.on_rtcm`), kept
for sites without the first. While the local stream is alive (a frame within `local_silence_s`)
the server's frames are dropped; when it falls silent they are injected. A frame is never
injected twice: one that came the other way within `duplicate_window_s` (the same bytes, late)
is dropped, counted as a duplicate.
"""

from __future__ import annotations

import logging
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, Literal

log = logging.getLogger(__name__)

Path = Literal["local", "server"]


@dataclass
class Corrections:
    """Chooses which path's frames reach `inject` (the autopilot's GPS_RTCM_DATA)."""

    inject: Callable[[bytes], Any]
    local_silence_s: float = 3.0
    duplicate_window_s: float = 5.0
    wall: Callable[[], float] = time.monotonic
    injected: dict[str, int] = field(default_factory=lambda: {"local": 0, "server": 0})
    skipped: int = 0  # server frames while the local stream was alive
    duplicates: int = 0
    using: Path | None = None  # the path of the last frame injected
    _local_last: float | None = None
    _recent: deque[tuple[float, Path, bytes]] = field(default_factory=deque)

    @property
    def local_alive(self) -> bool:
        """The local stream delivered a frame within `local_silence_s`."""
        last = self._local_last
        return last is not None and self.wall() - last < self.local_silence_s

    def from_local(self, frame: bytes) -> None:
        """A frame from the base's local stream."""
        self._local_last = self.wall()
        self._offer("local", frame)

    async def from_local_async(self, frame: bytes) -> None:
        """`from_local` as the reader's awaited frame callback."""
        self.from_local(frame)

    def from_server(self, frame: bytes) -> None:
        """A frame relayed by the server."""
        if self.local_alive:
            self.skipped += 1
            return
        self._offer("server", frame)

    def _offer(self, path: Path, frame: bytes) -> None:
        now = self.wall()
        recent = self._recent
        while recent and now - recent[0][0] > self.duplicate_window_s:
            recent.popleft()
        if any(p != path and f == frame for _, p, f in recent):
            self.duplicates += 1
            return
        recent.append((now, path, frame))
        if path != self.using:
            log.info("rtk: corrections now from the %s path", path)
            self.using = path
        self.injected[path] += 1
        self.inject(frame)
