"""The simulated autopilot's I/O shell: MAVLink 2 over TCP and UDP, and the simulation loop.

Addressing:
- TCP: a server (like ArduPilot SITL's 5760); every connected client gets the streams, at
  the rates it asked for (SET_MESSAGE_INTERVAL / REQUEST_DATA_STREAM are per link, as
  ArduPilot keeps them per channel).
- UDP: the vehicle listens on one port and sends to whoever last sent it a datagram (the
  companion connects with pymavlink ``udpout:127.0.0.1:PORT`` and must send first, e.g. its
  own HEARTBEAT). Until someone has sent, nothing goes out on UDP.

Telemetry rates and the mission-protocol timers run on wall time; flight runs on the
`SimClock` (speed factor), and falls behind it when the process is starved, as SITL's does (see
`MAX_CATCH_UP_WALL_S`). Replies go to the link the request came on; STATUSTEXT and
MISSION_ITEM_REACHED go to every link.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import math
import time
from collections.abc import AsyncIterator, Callable
from dataclasses import dataclass, field
from typing import Any

from pymavlink.dialects.v20 import ardupilotmega as mavlink

from asynckit.tasks import cancel_and_wait
from sim.clock import SimClock
from sim.vehicle.copter import Base, Copter, CopterConfig
from sim.vehicle.standalone import OpenPad
from sim.vehicle.streams import EXTENDED_SYS_STATE, HEARTBEAT, StreamScheduler, build

log = logging.getLogger(__name__)

WindFn = Callable[[float], tuple[float, float]]
MAX_SUBSTEP_S = 0.05
# ArduPilot SITL advances its physics one fixed frame per loop, reading and sending its MAVLink
# between frames, and sleeps while it is ahead of the wall clock; behind it, it catches up at most
# 0.1 s (SIM_Aircraft.cpp, sync_frame_time: the sleep debt is capped at -1e5 us) and otherwise
# lets simulated time fall behind. A process starved for a second on a busy machine therefore
# never flies seconds of simulated time in one step, deaf to the LANDING_TARGETs that arrived
# meanwhile. The own loop does the same: a step covers at most this much wall time more than
# its sleep, at the clock's speed; the rest is given up (`behind_s`).
MAX_CATCH_UP_WALL_S = 0.1


def _no_wind(t: float) -> tuple[float, float]:
    return 0.0, 0.0


@dataclass(eq=False)
class Link:
    """One peer: a TCP connection or the UDP endpoint (sending to its last sender), with its own rates."""

    name: str
    send_bytes: Callable[[bytes], None]
    mav: Any = field(default=None)
    streams: StreamScheduler = field(default_factory=lambda: StreamScheduler(time.monotonic()))

    def __post_init__(self) -> None:
        self.mav = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
        self.mav.robust_parsing = True

    def send(self, msg: Any) -> None:
        """Pack and send one message."""
        data = msg.pack(self.mav)
        self.mav.seq = (self.mav.seq + 1) % 256
        self.send_bytes(data)


class _Udp(asyncio.DatagramProtocol):
    def __init__(self, server: VehicleServer) -> None:
        self.server = server
        self.transport: asyncio.DatagramTransport | None = None
        self.peer: tuple[str, int] | None = None
        self.link = Link("udp", self._send)

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        self.transport = transport  # type: ignore[assignment]

    def _send(self, data: bytes) -> None:
        if self.transport is not None and self.peer is not None:
            self.transport.sendto(data, self.peer)

    def datagram_received(self, data: bytes, addr: tuple[str, int]) -> None:
        if self.server.muted():
            return
        self.peer = addr
        self.server.receive(self.link, data)


class VehicleServer:
    """Serves one `Copter` over MAVLink and runs its simulation loop."""

    def __init__(
        self,
        copter: Copter,
        clock: SimClock,
        *,
        host: str = "127.0.0.1",
        tcp_port: int = 0,
        udp_port: int = 0,
        wind_ne: WindFn = _no_wind,
        step_s: float = 0.01,
        own_loop: bool = True,
    ) -> None:
        self.copter = copter
        self.clock = clock
        self.host = host
        self.wind_ne = wind_ne
        self.step_s = step_s
        self.own_loop = own_loop  # False: the world calls `step(dt_sim)` from its loop
        self._want_tcp, self._want_udp = tcp_port, udp_port
        self.tcp_port = 0
        self.udp_port = 0
        self._links: set[Link] = set()
        self._udp: _Udp | None = None
        self._tcp_server: asyncio.Server | None = None
        self._task: asyncio.Task[None] | None = None
        self._writers: set[asyncio.StreamWriter] = set()
        self.received = 0
        self.behind_s = 0.0  # simulated seconds the own loop has given up (MAX_CATCH_UP_WALL_S)
        self._boots_seen = copter.boots
        self._mode_told = copter.mode  # the mode the links were last sent (habit mode_heartbeat)

    def fresh_streams(self) -> StreamScheduler:
        """A link's stream rates at boot: every default, or HEARTBEAT only (habit `streams_at_boot`)."""
        habits = self.copter.config.habits
        quiet = habits.streams_at_boot == "heartbeat"
        return StreamScheduler(time.monotonic(), quiet=quiet, at_once=not habits.stream_buckets)

    @property
    def udp_link(self) -> Link | None:
        """The UDP peer link (its stream rates are what UDP clients asked for)."""
        return self._udp.link if self._udp else None

    def muted(self) -> bool:
        """True while the fault 'stop answering MAVLink' is active, or the autopilot reboots."""
        now = time.monotonic()
        return self.copter.faults.muted(now) or self.copter.rebooting(now)

    async def start(self) -> None:
        """Bind the sockets and start the simulation loop."""
        loop = asyncio.get_running_loop()
        transport, proto = await loop.create_datagram_endpoint(
            lambda: _Udp(self), local_addr=(self.host, self._want_udp)
        )
        self._udp = proto
        proto.link.streams = self.fresh_streams()
        self._links.add(proto.link)
        self.udp_port = transport.get_extra_info("sockname")[1]
        self._tcp_server = await asyncio.start_server(self._tcp_client, self.host, self._want_tcp)
        self.tcp_port = self._tcp_server.sockets[0].getsockname()[1]
        if self.own_loop:
            self._task = asyncio.create_task(self._run(), name="sim-vehicle")
        log.info("simulated autopilot: MAVLink TCP %s, UDP %s", self.tcp_port, self.udp_port)

    async def close(self) -> None:
        """Stop the loop and close every socket."""
        await cancel_and_wait([self._task])
        if self._tcp_server:
            self._tcp_server.close()
        for w in list(self._writers):
            w.close()
        if self._udp and self._udp.transport:
            self._udp.transport.close()
        if self._tcp_server:
            with contextlib.suppress(Exception):
                await asyncio.wait_for(self._tcp_server.wait_closed(), 2.0)

    async def _tcp_client(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        def send(data: bytes) -> None:
            if not writer.is_closing():
                writer.write(data)

        link = Link(f"tcp:{writer.get_extra_info('peername')}", send)
        link.streams = self.fresh_streams()
        self._links.add(link)
        self._writers.add(writer)
        try:
            while data := await reader.read(4096):
                if not self.muted():
                    self.receive(link, data)
        except (ConnectionError, OSError) as err:
            log.info("MAVLink TCP client gone: %s", err)
        finally:
            self._links.discard(link)
            self._writers.discard(writer)
            writer.close()

    def receive(self, link: Link, data: bytes) -> None:
        """Bytes from a peer: parse, hand every message to the copter, send the replies."""
        try:
            msgs = link.mav.parse_buffer(data) or []
        except Exception:  # a garbled packet must never stop the vehicle
            log.warning("unparsable MAVLink bytes from %s", link.name, exc_info=True)
            return
        wall = time.monotonic()
        for msg in msgs:
            if msg.get_type() == "BAD_DATA":
                continue
            self.received += 1
            try:
                self.copter.handle(msg, link, wall)
            except Exception:
                log.exception("error handling %s", msg.get_type())
        self._flush()

    def _flush(self) -> None:
        out, self.copter.outbox = self.copter.outbox, []
        if self.muted():
            return
        for link, msg in out:
            for target in [link] if link is not None else list(self._links):
                try:
                    target.send(msg)
                except Exception:
                    log.warning("send to %s failed", target.name, exc_info=True)

    async def _run(self) -> None:
        last_sim = self.clock.now()
        most = (self.step_s + MAX_CATCH_UP_WALL_S) * self.clock.speed
        while True:
            await asyncio.sleep(self.step_s)
            now_sim = self.clock.now()
            elapsed = now_sim - last_sim
            try:
                self.step(min(elapsed, most))
            except Exception:
                log.exception("simulation step failed")
            if elapsed > most:
                self.behind_s += elapsed - most
            if elapsed - most >= 0.5:
                log.info(
                    "simulated autopilot: starved for %.2f s of wall time, %.2f s of simulated "
                    "time given up (%.1f s in all, as SITL's clock falls behind)",
                    elapsed / self.clock.speed, elapsed - most, self.behind_s,
                )  # fmt: skip
            last_sim = now_sim

    def step(self, dt_sim: float) -> None:
        """Advance the vehicle `dt_sim` simulated seconds (in small sub-steps), send due streams."""
        wall = time.monotonic()
        n = max(1, math.ceil(dt_sim / MAX_SUBSTEP_S))
        for _ in range(n):
            t = self.copter.t + dt_sim / n
            self.copter.tick(dt_sim / n, wall, self.wind_ne(t))
        if self.copter.boots != self._boots_seen:  # rebooted: every rate back to its boot value
            self._boots_seen = self.copter.boots
            for link in self._links:
                link.streams = self.fresh_streams()
        self._flush()
        if self.muted():
            return
        if self.copter.mode != self._mode_told and self.copter.config.habits.mode_heartbeat:
            for link in self._links:  # ArduPilot 4.x tells a mode change at once
                link.streams.send_once(HEARTBEAT)
        self._mode_told = self.copter.mode
        built: dict[int, Any] = {}
        silent = () if self.copter.config.habits.extended_sys_state else (EXTENDED_SYS_STATE,)
        for link in list(self._links):
            for msg_id in link.streams.due(wall):
                if msg_id in silent:
                    continue
                if msg_id not in built:
                    built[msg_id] = build(self.copter, msg_id)
                try:
                    link.send(built[msg_id])
                except Exception:
                    log.warning("send to %s failed", link.name, exc_info=True)


@contextlib.asynccontextmanager
async def run_vehicle(
    *,
    speed: float = 1.0,
    seed: int | None = None,
    base: Base | None = None,
    config: CopterConfig | None = None,
    host: str = "127.0.0.1",
    tcp_port: int = 0,
    udp_port: int = 0,
    wind_ne: WindFn = _no_wind,
) -> AsyncIterator[VehicleServer]:
    """Run a simulated vehicle on free ports (by default) for the duration of the block."""
    cfg = config or CopterConfig(seed=seed)
    copter = Copter(base or OpenPad(), cfg)
    server = VehicleServer(
        copter, SimClock(speed), host=host, tcp_port=tcp_port, udp_port=udp_port, wind_ne=wind_ne
    )
    await server.start()
    try:
        yield server
    finally:
        await server.close()
