"""A MAVLink 2 connection for the simulator's own use (asyncio, reconnecting): the world's read-only
watch on an external autopilot (`sim.follow`).

URLs, as pymavlink and the agent spell them:

- ``tcp:HOST:PORT`` — connect (ArduPilot SITL serves its serial ports as TCP 5760, 5762, 5763);
  reconnects every `RECONNECT_S` after a refusal or a drop,
- ``udpin:HOST:PORT`` (or ``udp:``) — listen; the autopilot (or MAVProxy ``--out``) sends first,
- ``udpout:HOST:PORT`` — send to the autopilot's UDP port first; it answers to our address.

`on_message(msg)` is called for every decoded message; `on_connect()` after each (re)connection.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
from collections.abc import Callable
from typing import Any

from pymavlink.dialects.v20 import ardupilotmega as mavlink

from asynckit.tasks import cancel_and_wait

log = logging.getLogger(__name__)

RECONNECT_S = 1.0
SCHEMES = ("tcp", "udpin", "udp", "udpout")


class BadUrl(ValueError):
    """A connection URL this link cannot use."""


def parse_url(url: str) -> tuple[str, str, int]:
    """``scheme:host:port`` -> (scheme, host, port); BadUrl naming what is wrong."""
    parts = url.split(":")
    if len(parts) != 3 or parts[0] not in SCHEMES:
        raise BadUrl(
            f"MAVLink URL {url!r}: expected one of {', '.join(SCHEMES)} as SCHEME:HOST:PORT"
        )
    scheme, host, port_s = parts
    try:
        port = int(port_s)
    except ValueError:
        raise BadUrl(f"MAVLink URL {url!r}: port {port_s!r} is not a number") from None
    if not 0 < port < 65536 or not host:
        raise BadUrl(f"MAVLink URL {url!r}: needs a host and a port in 1..65535")
    return scheme, host, port


class _Udp(asyncio.DatagramProtocol):
    def __init__(self, link: MavlinkLink, peer: tuple[str, int] | None) -> None:
        self.link, self.peer = link, peer
        self.transport: asyncio.DatagramTransport | None = None

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        self.transport = transport  # type: ignore[assignment]

    def datagram_received(self, data: bytes, addr: tuple[str, int]) -> None:
        first = self.peer is None
        self.peer = (addr[0], addr[1])
        if first:
            self.link.connected()
        self.link.received(data)

    def send(self, data: bytes) -> None:
        if self.transport is not None and self.peer is not None:
            self.transport.sendto(data, self.peer)


class MavlinkLink:
    """One MAVLink endpoint as a GCS-like peer of system `src_system`."""

    def __init__(
        self,
        url: str,
        on_message: Callable[[Any], None],
        on_connect: Callable[[], None] = lambda: None,
        src_system: int = 253,
        src_component: int = 191,  # MAV_COMP_ID_ONBOARD_COMPUTER
    ) -> None:
        self.scheme, self.host, self.port = parse_url(url)
        self.url = url
        self.on_message, self.on_connect = on_message, on_connect
        self.mav = mavlink.MAVLink(None, srcSystem=src_system, srcComponent=src_component)
        self.mav.robust_parsing = True
        self.is_connected = False
        self.received_count = 0
        self._writer: asyncio.StreamWriter | None = None
        self._udp: _Udp | None = None
        self._task: asyncio.Task[None] | None = None

    async def start(self) -> None:
        """Connect (TCP, retried in the background) or bind (UDP)."""
        if self.scheme == "tcp":
            self._task = asyncio.create_task(self._tcp_loop(), name=f"mavlink {self.url}")
            return
        loop = asyncio.get_running_loop()
        if self.scheme == "udpout":
            _, self._udp = await loop.create_datagram_endpoint(
                lambda: _Udp(self, (self.host, self.port)), local_addr=("0.0.0.0", 0)
            )
            self.connected()
        else:
            _, self._udp = await loop.create_datagram_endpoint(
                lambda: _Udp(self, None), local_addr=(self.host, self.port)
            )

    async def stop(self) -> None:
        """Close the connection."""
        await cancel_and_wait([self._task])
        if self._writer is not None:
            self._writer.close()
        if self._udp is not None and self._udp.transport is not None:
            self._udp.transport.close()

    def connected(self) -> None:
        """A (new) peer: tell the owner, which asks for what it wants."""
        self.is_connected = True
        log.info("MAVLink %s: connected", self.url)
        self.on_connect()

    def received(self, data: bytes) -> None:
        """Bytes in: decode and hand on every message."""
        try:
            msgs = self.mav.parse_buffer(data) or []
        except Exception:  # a garbled packet must not stop the watch
            log.warning("MAVLink %s: unparsable bytes", self.url, exc_info=True)
            return
        for msg in msgs:
            if msg.get_type() == "BAD_DATA":
                continue
            self.received_count += 1
            try:
                self.on_message(msg)
            except Exception:
                log.exception("MAVLink %s: handling %s failed", self.url, msg.get_type())

    def send(self, msg: Any) -> None:
        """Send one message (dropped while not connected)."""
        data = msg.pack(self.mav)
        self.mav.seq = (self.mav.seq + 1) % 256
        if self._writer is not None and not self._writer.is_closing():
            self._writer.write(data)
        elif self._udp is not None:
            self._udp.send(data)

    async def _tcp_loop(self) -> None:
        while True:
            try:
                reader, self._writer = await asyncio.open_connection(self.host, self.port)
            except OSError as err:
                log.info("MAVLink %s: %s; retrying", self.url, err)
                await asyncio.sleep(RECONNECT_S)
                continue
            self.connected()
            try:
                while data := await reader.read(4096):
                    self.received(data)
            except (ConnectionError, OSError) as err:
                log.info("MAVLink %s: dropped (%s)", self.url, err)
            finally:
                self.is_connected = False
                with contextlib.suppress(Exception):
                    self._writer.close()
                self._writer = None
            await asyncio.sleep(RECONNECT_S)
