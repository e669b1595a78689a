"""The MAVLink connection: pymavlink on a connection string, one reader thread, thread-safe sends.

Connection strings (pymavlink's, plus a serial shorthand):
- ``udpout:HOST:PORT`` — send to the autopilot's UDP port; it answers to our address
  (the simulator; also ArduPilot's ``--serialN udpclient:`` outputs reversed),
- ``udpin:0.0.0.0:14550`` — listen; the autopilot sends first (ArduPilot SITL's default output),
- ``tcp:HOST:5760`` — ArduPilot SITL's TCP port,
- ``serial:/dev/ttyUSB0:921600`` or a bare device path (default 57600 baud).
"""

from __future__ import annotations

import asyncio
import logging
import threading
from collections.abc import Callable
from typing import Any

from pymavlink import mavutil

log = logging.getLogger(__name__)

MAV_COMP_ID_ONBOARD_COMPUTER = 191


def parse_connection(url: str) -> tuple[str, int | None]:
    """A connection string -> (pymavlink device, baud or None)."""
    if url.startswith("serial:"):
        rest = url[len("serial:") :]
        device, _, baud = rest.rpartition(":")
        if device and baud.isdigit():
            return device, int(baud)
        return rest, 57600
    if url.startswith("/dev/") or url.upper().startswith("COM"):
        return url, 57600
    return url, None


class MavlinkLink:
    """Owns the pymavlink connection and the reader thread, which feeds `queue` in the event loop."""

    def __init__(
        self,
        url: str,
        queue: asyncio.Queue[Any],
        *,
        source_system: int = 1,
        source_component: int = MAV_COMP_ID_ONBOARD_COMPUTER,
    ) -> None:
        self.url = url
        self.queue = queue
        self._source = (source_system, source_component)
        self._conn: Any = None
        self._thread: threading.Thread | None = None
        self._stop = threading.Event()
        self._send_lock = threading.Lock()
        self._loop: asyncio.AbstractEventLoop | None = None
        self._reconnecting = False
        self.on_reconnect: Callable[[], None] | None = None  # in the loop, after a TCP reconnect

    async def open(self) -> None:
        """Open the connection (in a thread: TCP connect and serial open block) and start reading."""
        self._loop = asyncio.get_running_loop()
        device, baud = parse_connection(self.url)
        kwargs: dict[str, Any] = {
            "source_system": self._source[0],
            "source_component": self._source[1],
            "dialect": "ardupilotmega",
            "autoreconnect": True,
        }
        if baud is not None:
            kwargs["baud"] = baud
        self._conn = await asyncio.to_thread(mavutil.mavlink_connection, device, **kwargs)
        self._conn.mav.robust_parsing = True
        if isinstance(self._conn, mavutil.mavtcp):
            self._guard_reconnect(self._conn)
        self._thread = threading.Thread(
            target=self._read, name=f"mavlink-reader {self.url}", daemon=True
        )
        self._thread.start()

    def _guard_reconnect(self, conn: Any) -> None:
        """Only the reader thread reconnects a TCP link; a send meanwhile is dropped.

        pymavlink's TCP link reconnects from whichever thread meets the closed socket. With a
        sender (RTCM corrections, heartbeats) and the reader both doing so, one thread's
        connect() lands on the socket the other has just connected, and the send fails with
        "[Errno 106] Transport endpoint is already connected". Here the reader alone
        reconnects, and a send finding the link down raises ConnectionError ("reconnecting").
        """
        reconnect = conn.reconnect
        self._reconnecting = False

        def guarded() -> None:
            if threading.current_thread() is not self._thread:
                raise ConnectionError(f"{self.url}: link down, reconnecting")
            with self._send_lock:
                self._reconnecting = True
            try:
                reconnect()
            finally:
                with self._send_lock:
                    self._reconnecting = False
            if self.on_reconnect is not None and self._loop is not None:
                self._loop.call_soon_threadsafe(self.on_reconnect)

        conn.reconnect = guarded

    def _read(self) -> None:
        loop, conn = self._loop, self._conn
        assert loop is not None
        while not self._stop.is_set():
            try:
                msg = conn.recv_match(blocking=True, timeout=0.2)
            except Exception:  # a dying socket or a garbled byte must not kill the reader
                if self._stop.is_set():
                    return
                log.warning("MAVLink read failed", exc_info=True)
                self._stop.wait(0.2)
                continue
            if msg is None or msg.get_type() == "BAD_DATA":
                continue
            try:
                loop.call_soon_threadsafe(self.queue.put_nowait, msg)
            except RuntimeError:  # the loop is closed: we are shutting down
                return

    def send(self, build: Callable[[Any], Any]) -> None:
        """Send one message: `build(mav)` calls a pymavlink ``*_send`` method."""
        if self._conn is None:
            raise RuntimeError("link not open")
        with self._send_lock:
            if self._reconnecting or getattr(self._conn, "port", True) is None:
                raise ConnectionError(f"{self.url}: link down, reconnecting")
            build(self._conn.mav)

    async def close(self) -> None:
        """Stop the reader thread and close the connection."""
        self._stop.set()
        if self._thread is not None:
            await asyncio.to_thread(self._thread.join, 2.0)
        if self._conn is not None:
            try:
                self._conn.close()
            except Exception:
                log.debug("closing the MAVLink connection failed", exc_info=True)
