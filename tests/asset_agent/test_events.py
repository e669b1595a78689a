"""Pure event derivation from successive UavState values."""

from __future__ import annotations

from dataclasses import replace

from asset_agent.autopilot.state import Notification, UavState
from asset_agent.events import EventLimits, EventTracker, derive_events, events_from_notification

GROUND = UavState(
    link_up=True, custom_mode=4, mode="GUIDED", landed_state="ON_GROUND", battery_pct=95
)


def kinds(prev: UavState, cur: UavState) -> list[str]:
    return [e.kind for e in derive_events(prev, cur)]


def test_a_whole_flight_gives_each_event_once() -> None:
    armed = replace(GROUND, armed=True, system_status=4)
    takeoff = replace(armed, landed_state="TAKEOFF", mode="AUTO", mission_state="ACTIVE")
    flying = replace(takeoff, landed_state="IN_AIR")
    landing = replace(flying, landed_state="LANDING", mode="RTL", mission_state="ACTIVE")
    down = replace(landing, landed_state="ON_GROUND", mission_state="COMPLETE")
    disarmed = replace(down, armed=False, system_status=3)
    tracker = EventTracker()
    seen = []
    for s in (GROUND, armed, takeoff, flying, landing, down, disarmed, disarmed):
        seen += [e.kind for e in tracker.update(s)]
    assert seen == [
        "armed", "took_off", "landing", "landed",
        "mission_finished", "disarmed",
    ]  # fmt: skip


def test_first_link_is_not_a_recovery_but_a_later_one_is() -> None:
    assert kinds(UavState(), GROUND) == []
    lost = replace(GROUND, link_up=False)
    assert kinds(GROUND, lost) == ["autopilot_lost"]
    assert kinds(lost, GROUND) == ["autopilot_recovered"]


def test_low_battery_fires_once_when_crossing_the_threshold() -> None:
    limits = EventLimits(low_battery_pct=30)
    a, b, c = (replace(GROUND, battery_pct=p) for p in (31, 29, 20))
    assert [e.kind for e in derive_events(a, b, limits)] == ["low_battery"]
    assert derive_events(a, b, limits)[0].detail["battery_pct"] == 29
    assert derive_events(b, c, limits) == []


def test_failsafe_from_critical_status() -> None:
    critical = replace(GROUND, armed=True, system_status=5)
    assert "failsafe" in kinds(replace(GROUND, armed=True, system_status=4), critical)


def test_waypoint_reached_from_notification() -> None:
    events = events_from_notification(Notification("item_reached", index=3))
    assert [(e.kind, e.detail["index"]) for e in events] == [("waypoint_reached", 3)]
    assert events_from_notification(Notification("statustext", "hello")) == []


def test_out_of_order_streams_keep_the_logical_order() -> None:
    # EXTENDED_SYS_STATE says TAKEOFF before the HEARTBEAT says armed
    climbing = replace(GROUND, landed_state="TAKEOFF")
    assert kinds(GROUND, climbing) == []
    assert kinds(climbing, replace(climbing, armed=True)) == ["armed", "took_off"]
    # the HEARTBEAT says disarmed before EXTENDED_SYS_STATE says ON_GROUND
    landing = replace(GROUND, armed=True, landed_state="LANDING")
    disarmed = replace(landing, armed=False)
    assert kinds(landing, disarmed) == ["landed", "disarmed"]
    assert kinds(disarmed, replace(disarmed, landed_state="ON_GROUND")) == []


def test_the_last_item_reached_comes_before_the_mission_end_it_causes() -> None:
    """MISSION_ITEM_REACHED of the last waypoint and the state that says the mission complete
    arrive within one telemetry tick; the events keep the order in which they were heard."""
    flying = replace(GROUND, armed=True, landed_state="IN_AIR", mode="AUTO", mission_state="ACTIVE")
    done = replace(flying, mission_state="COMPLETE")
    tracker = EventTracker()
    tracker.update(flying)
    # as the client queues them: each with the state when it was heard
    reached = Notification("item_reached", index=2, state=flying)
    events = tracker.feed([reached], done)
    assert [(e.kind, e.detail.get("index")) for e in events] == [
        ("waypoint_reached", 2), ("mission_finished", None),
    ]  # fmt: skip


def test_a_state_change_heard_before_a_notification_comes_before_it() -> None:
    ground = replace(GROUND, mode="AUTO")
    armed = replace(ground, armed=True, system_status=4)
    tracker = EventTracker()
    tracker.update(ground)
    note = Notification("item_reached", index=0, state=armed)
    events = tracker.feed([note], replace(armed, landed_state="TAKEOFF"))
    assert [e.kind for e in events] == ["armed", "waypoint_reached", "took_off"]


def test_an_agent_started_in_flight_tells_no_arming_take_off_or_landing_it_did_not_see() -> None:
    """What the agent first hears is no change (a restart in flight): the HEARTBEAT says armed
    before EXTENDED_SYS_STATE says in the air, or on a landing; what follows is told as usual."""
    tracker = EventTracker()
    first = replace(GROUND, armed=True, system_status=4, mode="AUTO", landed_state="UNDEFINED")
    flying = replace(first, landed_state="IN_AIR")
    assert tracker.update(UavState()) == []  # no HEARTBEAT yet
    assert tracker.update(first) == [] and tracker.update(flying) == []
    landing = replace(flying, landed_state="LANDING")
    down = replace(landing, landed_state="ON_GROUND", armed=False, system_status=3)
    assert [e.kind for e in tracker.update(landing) + tracker.update(down)] == [
        "landing", "landed", "disarmed",
    ]  # fmt: skip
    # a restart in the final descent: no "landing" for it
    again = EventTracker()
    assert again.update(replace(first, landed_state="LANDING")) == []
