"""Events operators see (refusals, faults, link, E-stop, landing, charging, power), and the bus.

`diff_events(prev, new)` is pure: it derives the events between two snapshots.
"""

from __future__ import annotations

import asyncio
import time
from collections import deque
from collections.abc import AsyncIterator
from dataclasses import dataclass, field
from enum import StrEnum
from typing import Any

from base_station.plc.codec import fault_names
from base_station.plc.registers import ChargerState
from base_station.snapshot import Snapshot


class EventKind(StrEnum):
    """What happened."""

    REFUSAL = "refusal"
    MOTION_FAILED = "motion_failed"
    PLC_INTERLOCK_REFUSED = "plc_interlock_refused"
    FAULT = "fault"
    FAULT_CLEARED = "fault_cleared"
    WATCHDOG_RECOVERED = "watchdog_recovered"
    PLC_LINK_LOST = "plc_link_lost"
    PLC_LINK_RESTORED = "plc_link_restored"
    ESTOP = "estop"
    ESTOP_RELEASED = "estop_released"
    LANDING_CONFIRMED = "landing_confirmed"
    CHARGE_COMPLETE = "charge_complete"
    POWER_SOURCE_CHANGED = "power_source_changed"


@dataclass(frozen=True)
class Event:
    """One event: its kind, a human-readable message, structured data, unix time."""

    kind: EventKind
    message: str
    data: dict[str, Any] = field(default_factory=dict)
    ts: float = field(default_factory=time.time)


def diff_events(prev: Snapshot | None, new: Snapshot) -> list[Event]:
    """The events implied by going from `prev` to `new`."""
    out: list[Event] = []
    was_up = prev.link_up if prev is not None else None
    if not new.link_up and was_up is not False:
        out.append(
            Event(
                EventKind.PLC_LINK_LOST,
                f"PLC link lost: {new.link_error}",
                {"error": new.link_error},
            )
        )
    if new.link_up and was_up is False:
        out.append(Event(EventKind.PLC_LINK_RESTORED, "PLC link restored"))
    if not new.link_up or new.plc is None:
        return out
    p = prev.plc if prev is not None else None  # last known, also across an outage
    s = new.plc
    old_bits = int(p.fault_bits) if p is not None else 0
    raised, cleared = int(s.fault_bits) & ~old_bits, old_bits & ~int(s.fault_bits)
    if raised:
        names = fault_names(raised)
        out.append(
            Event(
                EventKind.FAULT,
                f"PLC fault: {', '.join(names)}",
                {"faults": list(names), "fault_bits": int(s.fault_bits)},
            )
        )
    if cleared:
        names = fault_names(cleared)
        out.append(
            Event(
                EventKind.FAULT_CLEARED,
                f"PLC fault cleared: {', '.join(names)}",
                {"faults": list(names), "fault_bits": int(s.fault_bits)},
            )
        )
    if s.estop_active and (p is None or not p.estop_active):
        out.append(Event(EventKind.ESTOP, "E-stop active: all motion stopped"))
    if p is not None and p.estop_active and not s.estop_active:
        out.append(Event(EventKind.ESTOP_RELEASED, "E-stop released (reset_faults to clear)"))
    if p is not None and s.interlock_refused and not p.interlock_refused:
        out.append(Event(EventKind.PLC_INTERLOCK_REFUSED, "the PLC refused a motion command"))
    if (
        p is not None
        and s.charger_state is ChargerState.COMPLETE
        and p.charger_state is not ChargerState.COMPLETE
    ):
        out.append(
            Event(
                EventKind.CHARGE_COMPLETE,
                "UAV charge complete",
                {"uav_battery_pct": s.uav_battery_soc_pct},
            )
        )
    if p is not None and s.power_source != p.power_source:
        src = s.power_source.name.lower() if s.power_source is not None else "unknown"
        out.append(
            Event(
                EventKind.POWER_SOURCE_CHANGED,
                f"power source: {src}",
                {"source": src, "base_battery_pct": s.base_battery_soc_pct},
            )
        )
    landed = new.landing is not None and new.landing.confirmed
    was_landed = prev is not None and prev.landing is not None and prev.landing.confirmed
    if landed and not was_landed and new.landing is not None:
        out.append(
            Event(
                EventKind.LANDING_CONFIRMED,
                f"landing confirmed: {new.landing.mass_g:.0f} g stable",
                {"mass_g": new.landing.mass_g},
            )
        )
    return out


class Subscription:
    """A registered listener of the bus: iterate it; `close()` (or leave `async with`) ends it."""

    def __init__(self, bus: EventBus, maxsize: int = 1000) -> None:
        self._bus = bus
        self.queue: asyncio.Queue[Event] = asyncio.Queue(maxsize)
        bus._subs.add(self)

    def close(self) -> None:
        """Stop receiving events."""
        self._bus._subs.discard(self)

    def __aiter__(self) -> AsyncIterator[Event]:
        return self

    async def __anext__(self) -> Event:
        return await self.queue.get()

    async def __aenter__(self) -> Subscription:
        return self

    async def __aexit__(self, *exc: object) -> None:
        self.close()


class EventBus:
    """Fan-out of events to subscribers, keeping a short history."""

    def __init__(self, history: int = 500) -> None:
        self._subs: set[Subscription] = set()
        self.history: deque[Event] = deque(maxlen=history)

    def publish(self, event: Event) -> None:
        """Deliver `event` to every subscriber (a full queue drops its oldest event)."""
        self.history.append(event)
        for sub in list(self._subs):
            if sub.queue.full():
                sub.queue.get_nowait()
            sub.queue.put_nowait(event)

    def subscribe(self) -> Subscription:
        """A new subscription, registered at once (no event published after this is missed)."""
        return Subscription(self)
