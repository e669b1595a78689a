"""The coordinator: owns the PLC connection, the poll loop and the watchdog writer.

It polls the PLC at `plc.poll_hz`, turns each read into an immutable `Snapshot`, derives
events from successive snapshots and publishes them on its `EventBus`. It never writes a
motion coil by itself: on start and on every reconnect it only reads (and feeds the
watchdog), so a restart or a reconnect cannot start any motion.

The one coil it writes unasked is FAULT_RESET, to recover the PLC from a watchdog latch its
master's absence caused (a daemon killed or frozen, a cut cable): only when that is the only
latched fault, the E-stop is released and the watchdog is being fed again (`recoverable_latch`,
`WatchdogWriter.fed`), at most once every `RESET_RETRY_S`. Otherwise the latch would outlive the
outage and refuse every later command, `close` included, until a person came.

The link counts as down when a request fails or times out, and also when PLC_HEARTBEAT
stays frozen for `plc.heartbeat_timeout_s` (the PLC answers but its CPU is not running).
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import time

from asynckit.roundtrips import RoundTrips
from asynckit.tasks import cancel_and_wait
from base_station.config import StationConfig
from base_station.devices.axis import AxisTracker
from base_station.devices.lift import LIFT
from base_station.devices.panels import PANELS
from base_station.devices.scale import LandingDetector
from base_station.events import Event, EventBus, EventKind, diff_events
from base_station.plc import (
    Coil,
    HoldingRegister,
    PlcClient,
    PlcLinkError,
    PlcState,
    WatchdogWriter,
)
from base_station.plc.watchdog import recoverable_latch
from base_station.snapshot import Snapshot

log = logging.getLogger(__name__)

RESET_RETRY_S = 2.0  # a FAULT_RESET that did not clear the watchdog latch is retried after this


class Coordinator:
    """Poll loop + snapshots + events; the only owner of the `PlcClient`."""

    def __init__(self, config: StationConfig, client: PlcClient | None = None) -> None:
        self.config = config
        p = config.plc
        self.client = client or PlcClient(p.host, p.port, p.unit, p.timeout_s)
        self.watchdog = WatchdogWriter(self.client, p.watchdog_period_s)
        self.events = EventBus()
        u = config.uav
        self.landing = LandingDetector(
            u.min_mass_g, u.max_mass_g, u.stable_s, u.stable_tolerance_g, u.scale_tare_g
        )
        self.trackers = {"panels": AxisTracker(PANELS), "lift": AxisTracker(LIFT)}
        self.snapshot = Snapshot(0, time.monotonic(), time.time(), False, "not connected yet", None)
        self._published_any = False
        self._tick = asyncio.Event()
        self._tasks: list[asyncio.Task[None]] = []
        self.polls = 0
        self._heartbeat: tuple[int, float] | None = None  # last value, when it last changed
        self._reset_at: float | None = None  # when FAULT_RESET was last written for the watchdog
        self.watchdog_recoveries = 0
        self.read_round_trips = RoundTrips()  # one poll's read of the PLC's state, over Modbus TCP

    # --- lifecycle -----------------------------------------------------------------------

    async def start(self) -> None:
        """Start polling and feeding the watchdog (reads only: no command is written)."""
        self._tasks = [
            asyncio.ensure_future(self._poll_loop()),
            asyncio.ensure_future(self.watchdog.run()),
        ]

    async def stop(self) -> None:
        """Stop the loops and close the connection."""
        await cancel_and_wait(self._tasks)
        self._tasks = []
        self.client.close()

    # --- polling -------------------------------------------------------------------------

    async def _poll_loop(self) -> None:
        period = 1.0 / self.config.plc.poll_hz
        while True:
            started = time.monotonic()
            try:
                await self.poll_once()
                await self.clear_watchdog_latch()
            except PlcLinkError as err:  # the next poll reports the link
                log.debug("coordinator: watchdog recovery not written: %s", err)
            except Exception:  # a bug in one poll must not end polling
                log.exception("coordinator: poll failed")
            if not self.snapshot.link_up:
                await asyncio.sleep(self.config.plc.reconnect_s)
            else:
                await asyncio.sleep(max(0.0, period - (time.monotonic() - started)))

    async def poll_once(self) -> Snapshot:
        """Connect if needed, read the PLC once, publish the snapshot."""
        started = time.monotonic()
        try:
            if not self.client.connected:
                await self.client.connect()
                log.info("coordinator: connected to PLC %s:%s", self.client.host, self.client.port)
            asked = time.monotonic()
            plc = await self.client.read_state()
            self.read_round_trips.observe(time.monotonic() - asked)
        except PlcLinkError as err:
            self._heartbeat = None
            self._publish(started, False, str(err), self.snapshot.plc)
            return self.snapshot
        stale = self._heartbeat_stale(plc.heartbeat, started)
        if stale:
            self._publish(started, False, stale, plc)
        else:
            self._publish(started, True, "", plc)
        return self.snapshot

    def _heartbeat_stale(self, value: int, now: float) -> str:
        """A reason when PLC_HEARTBEAT has not moved for `heartbeat_timeout_s`, else ""."""
        if self._heartbeat is None or self._heartbeat[0] != value:
            self._heartbeat = (value, now)
            return ""
        frozen = now - self._heartbeat[1]
        if frozen > self.config.plc.heartbeat_timeout_s:
            return f"PLC heartbeat frozen for {frozen:.1f} s (PLC CPU not running)"
        return ""

    def _publish(self, started: float, link_up: bool, error: str, plc: PlcState | None) -> None:
        self.polls += 1
        prev = self.snapshot if self._published_any else None
        panels = self.trackers["panels"].update(plc) if link_up else None
        lift = self.trackers["lift"].update(plc) if link_up else None
        landing = None
        if plc is not None and link_up:
            landing, _ = self.landing.update(started, plc.scale_mass_g)
        elif prev is not None:
            landing = prev.landing
        snap = Snapshot(
            seq=self.snapshot.seq + 1,
            read_started=started,
            ts=time.time(),
            link_up=link_up,
            link_error=error,
            plc=plc,
            panels=panels if link_up else (prev.panels if prev else None),
            lift=lift if link_up else (prev.lift if prev else None),
            landing=landing,
        )
        self.snapshot = snap
        self._published_any = True
        for event in diff_events(prev, snap):
            log.info("event %s: %s", event.kind, event.message)
            self.events.publish(event)
        tick, self._tick = self._tick, asyncio.Event()
        tick.set()

    async def wait_next(self, after_seq: int, within: float = 1.0) -> Snapshot:
        """The first snapshot newer than `after_seq`, or the current one after `within` seconds."""
        deadline = time.monotonic() + within
        while self.snapshot.seq <= after_seq:
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                break
            with contextlib.suppress(TimeoutError):
                await asyncio.wait_for(self._tick.wait(), remaining)
        return self.snapshot

    async def wait_link(self, within: float) -> Snapshot:
        """The current snapshot, or with the link down the first one with it up within `within`
        seconds (the current one, still down, after that)."""
        deadline = time.monotonic() + within
        snap = self.snapshot
        while not snap.link_up and time.monotonic() < deadline:
            snap = await self.wait_next(snap.seq, max(0.01, deadline - time.monotonic()))
        return snap

    async def wait_fresh(self, after: float, within: float = 2.0) -> Snapshot:
        """The first snapshot whose read started after monotonic time `after`."""
        deadline = time.monotonic() + within
        snap = self.snapshot
        while snap.read_started < after and time.monotonic() < deadline:
            snap = await self.wait_next(snap.seq, max(0.01, deadline - time.monotonic()))
        return snap

    # --- recovering the PLC from a watchdog latch ------------------------------------------

    def _watchdog_recovery_due(self, now: float) -> bool:
        snap = self.snapshot
        return (
            snap.link_up
            and snap.plc is not None
            and recoverable_latch(snap.plc)
            and self.watchdog.fed(now)
            and (self._reset_at is None or now - self._reset_at >= RESET_RETRY_S)
        )

    async def clear_watchdog_latch(self) -> float | None:
        """Write FAULT_RESET when only the watchdog fault is latched and the watchdog is fed again;
        returns when it was written (None when not due). Nothing moves: motion must be commanded."""
        now = time.monotonic()
        if not self._watchdog_recovery_due(now):
            return None
        self._reset_at = now
        written = await self.write_coil(Coil.FAULT_RESET, True)
        self.watchdog_recoveries += 1
        message = (
            "PLC watchdog fault cleared: it latched while no master fed the PLC (daemon restarted "
            "or link lost); the daemon feeds it again and nothing else is latched, so FAULT_RESET "
            "was written (nothing moves until commanded)"
        )
        self.emit(Event(EventKind.WATCHDOG_RECOVERED, message, {"faults": ["WATCHDOG"]}))
        return written

    async def before_motion(self, link_wait_s: float = 0.0) -> Snapshot:
        """The snapshot a motion command is checked against: the current one (with the link down,
        the first one up within `link_wait_s`), or, when a recoverable watchdog latch would
        refuse it, the first one read after clearing it."""
        snap = await self.wait_link(link_wait_s)
        if snap.link_up and snap.plc is not None and recoverable_latch(snap.plc):
            return await self.recover_watchdog()
        return snap

    async def recover_watchdog(self, within: float = 2.0) -> Snapshot:
        """For a command refused by a watchdog latch: clear it if it may be cleared, and return
        the first snapshot read after the reset (or the current one when there is nothing to do).

        Right after a (re)connect the watchdog may not be fed yet: wait for that (up to `within`).
        """
        deadline = time.monotonic() + within
        snap = self.snapshot
        while (
            snap.link_up
            and snap.plc is not None
            and recoverable_latch(snap.plc)
            and not self.watchdog.fed()
            and time.monotonic() < deadline
        ):
            snap = await self.wait_next(snap.seq, max(0.01, deadline - time.monotonic()))
        written = await self.clear_watchdog_latch()
        if written is None and self._reset_at is not None:
            written = self._reset_at  # the poll loop has just written it: see its effect
        if written is None:
            return self.snapshot
        return await self.wait_fresh(written, max(0.5, deadline - time.monotonic()))

    # --- writes (used by the Station only) -----------------------------------------------

    def emit(self, event: Event) -> None:
        """Publish an event raised outside the poll loop (refusals, motion failures)."""
        log.info("event %s: %s", event.kind, event.message)
        self.events.publish(event)

    async def write_coil(self, coil: Coil, value: bool) -> float:
        """Write a coil; returns the monotonic time the write was acknowledged."""
        if not self.snapshot.link_up:
            raise PlcLinkError("PLC link down")
        await self.client.write_coil(coil, value)
        return time.monotonic()

    async def write_register(self, register: HoldingRegister, value: int) -> float:
        """Write a holding register; returns the monotonic time the write was acknowledged."""
        if not self.snapshot.link_up:
            raise PlcLinkError("PLC link down")
        await self.client.write_register(register, value)
        return time.monotonic()
