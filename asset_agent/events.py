"""Pure derivation of the agent's events from successive UavState values and notifications.

Kinds: armed, took_off, waypoint_reached, mission_finished, landing, landed, disarmed,
failsafe, low_battery, fence_breach, autopilot_lost, autopilot_recovered; precision landing
adds landing_aborted, precland_silent and landed_without_precision (precland/supervisor.py,
precland/silence.py).

    tracker = EventTracker(EventLimits(low_battery_pct=30))
    # on every telemetry tick: the Notifications heard since the last one, and the state now
    events = tracker.feed(notes, autopilot.state)
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Any

from asset_agent.autopilot.state import Notification, UavState

EVENT_KINDS = (
    "armed", "took_off", "waypoint_reached", "mission_finished", "landing", "landed",
    "disarmed", "failsafe", "low_battery", "fence_breach", "autopilot_lost",
    "autopilot_recovered", "landing_aborted", "precland_silent",
    "landed_without_precision",
)  # fmt: skip


@dataclass(frozen=True)
class Event:
    """One event: its kind and a read-only detail mapping."""

    kind: str
    detail: Mapping[str, Any] = field(default_factory=lambda: MappingProxyType({}))


@dataclass(frozen=True)
class EventLimits:
    """Thresholds for derived events."""

    low_battery_pct: float = 30.0


def _event(kind: str, **detail: Any) -> Event:
    return Event(kind, MappingProxyType(detail))


def _flying(s: UavState) -> bool:
    return s.armed and s.in_air


def derive_events(prev: UavState, cur: UavState, limits: EventLimits | None = None) -> list[Event]:
    """The events implied by going from `prev` to `cur`, in a stable order."""
    limits = limits or EventLimits()
    out: list[Event] = []
    if not prev.link_up and cur.link_up and prev.custom_mode is not None:
        out.append(_event("autopilot_recovered"))
    if prev.link_up and not cur.link_up:
        out.append(_event("autopilot_lost"))
    # what the agent first hears is no change: started (or restarted) with the vehicle armed in
    # the air, it did not arm, take off or start landing then
    heard, placed = prev.mode_known, prev.landed_known
    if heard and not prev.armed and cur.armed:
        out.append(_event("armed", mode=cur.mode))
    # HEARTBEAT (armed) and EXTENDED_SYS_STATE (landed state) arrive independently, so the
    # flight phases combine both: airborne means armed and in the air; a disarm while the
    # landed state still says "in the air" is a landing whose ON_GROUND report is late.
    if placed and heard and not _flying(prev) and _flying(cur) and cur.landed_state != "LANDING":
        out.append(_event("took_off", mode=cur.mode))
    if placed and prev.landed_state != "LANDING" and cur.landed_state == "LANDING":
        out.append(_event("landing", mode=cur.mode))
    if _flying(prev) and (cur.landed_state == "ON_GROUND" or not cur.armed):
        out.append(_event("landed", lat=cur.lat, lon=cur.lon))
    if prev.mission_state != "COMPLETE" and cur.mission_state == "COMPLETE":
        out.append(_event("mission_finished", total=cur.mission_total))
    if not prev.failsafe and cur.failsafe:
        out.append(_event("failsafe", mode=cur.mode, system_status=cur.system_status))
    thr = limits.low_battery_pct
    was_ok = prev.battery_pct is None or prev.battery_pct >= thr
    if was_ok and cur.battery_pct is not None and cur.battery_pct < thr:
        out.append(_event("low_battery", battery_pct=cur.battery_pct, threshold_pct=thr))
    # FENCE_STATUS counts breaches (from boot): a higher count than the last one heard is a new
    # breach, even when the status that carries it says the vehicle is already back inside
    if (
        prev.fence_breach_count is not None
        and cur.fence_breach_count is not None
        and cur.fence_breach_count > prev.fence_breach_count
    ):
        out.append(
            _event(
                "fence_breach",
                breach_type=cur.fence_breach_type,
                breach_count=cur.fence_breach_count,
                mode=cur.mode,
                lat=cur.lat,
                lon=cur.lon,
                alt_rel_m=cur.alt_rel,
            )
        )
    if prev.armed and not cur.armed:
        out.append(_event("disarmed"))
    return out


def events_from_notification(note: Notification) -> list[Event]:
    """Events carried by a notification (link changes come from the state instead)."""
    if note.kind == "item_reached":
        return [_event("waypoint_reached", index=note.index)]
    return []


class EventTracker:
    """Keeps the previous state so callers just feed states and notifications."""

    def __init__(self, limits: EventLimits | None = None) -> None:
        self.limits = limits or EventLimits()
        self.prev = UavState()

    def update(self, state: UavState) -> list[Event]:
        """Events since the last state fed in."""
        events = derive_events(self.prev, state, self.limits)
        self.prev = state
        return events

    def notification(self, note: Notification) -> list[Event]:
        """Events from one notification."""
        return events_from_notification(note)

    def feed(self, notes: Iterable[Notification], state: UavState) -> list[Event]:
        """Events in the order they happened: for each notification (oldest first) the state
        changes heard before it, then its own events; then the changes since the last one. (The
        last item's MISSION_ITEM_REACHED and the mission's end come in one burst: derived from
        the latest state alone, the end would come before the item.)"""
        events: list[Event] = []
        for note in notes:
            if note.state is not None:
                events += self.update(note.state)
            events += self.notification(note)
        return events + self.update(state)
