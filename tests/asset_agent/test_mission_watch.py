"""asset_agent/autopilot/mission_watch.py: a mission's end is its own, never the last flight's.

The stale sequences are what a link shows right after a flight (and what the simulator's
`stale_mission` fault replays): the old mission's last MISSION_CURRENT (COMPLETE, on its last
item) and MISSION_ITEM_REACHED, before the new upload's ack, after the arming, right after the
start, repeated."""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import replace

import pytest

from asset_agent.autopilot.mission_watch import MissionWatch
from asset_agent.autopilot.state import Notification, UavState
from asset_agent.events import EventTracker

HOME = (41.178, -8.596)
# the survey's shape: takeoff, speed, waypoints, RTL (server numbering); navigation: 0, 2, 3, 4, 5
SURVEY = [22, 178, 16, 16, 16, 20]
LIFT = UavState(
    link_up=True, armed=False, system_status=3, mode="GUIDED", alt_rel=0.0, vd=0.0,
    lat=HOME[0], lon=HOME[1], home_lat=HOME[0], home_lon=HOME[1], landed_state="ON_GROUND",
    mission_total=6,
)  # fmt: skip
FLYING = replace(LIFT, armed=True, mode="AUTO", alt_rel=15.0, landed_state="IN_AIR")
# what the autopilot says of the last flight: on its last item (RTL), COMPLETE
OLD_END = {"mission_current": 5, "mission_state": "COMPLETE"}


def on(item: int, **kw: object) -> UavState:
    """Flying the mission in AUTO on `item`, the autopilot saying ACTIVE."""
    fields: dict[str, object] = {"mission_current": item, "mission_state": "ACTIVE", **kw}
    return replace(FLYING, **fields)  # type: ignore[arg-type]


class Flight:
    """Feeds a MissionWatch as the adapter does and keeps the events derived from it."""

    def __init__(self, commands: list[int] = SURVEY, reported: bool = True, opaque_id: int = 0):
        self.w = MissionWatch()
        self.w.reported = reported
        self.w.uploaded(len(commands), commands, opaque_id)
        self.tracker = EventTracker()
        self.state = replace(LIFT, **OLD_END)  # type: ignore[arg-type]
        self.tracker.update(replace(self.state, mission_state="COMPLETE"))  # the last flight's
        self.events: list[tuple[str, object]] = []
        self.now = 0.0

    def see(self, *states: UavState) -> UavState:
        """States in turn (each a message's worth), as Autopilot._handle applies them."""
        for cur in states:
            self.now += 0.1
            new = self.w.on_change(self.state, cur, self.now)
            notes = []
            reached = self.w.touched_down(self.state, new)
            if reached is not None:
                notes.append(Notification("item_reached", index=reached, state=self.state))
            self._events(notes, new)
            self.state = new
        return self.state

    def reach(self, *seqs: int) -> list[bool]:
        """MISSION_ITEM_REACHED(seq) in turn: whether each was the mission's own."""
        ours = []
        for seq in seqs:
            new, own = self.w.on_reached(self.state, seq)
            notes = [Notification("item_reached", index=seq - 1, state=self.state)] if own else []
            self._events(notes, new)
            self.state = new
            ours.append(own)
        return ours

    def _events(self, notes: Iterable[Notification], state: UavState) -> None:
        for e in self.tracker.feed(notes, state):
            self.events.append((e.kind, e.detail.get("index")))

    def kinds(self) -> list[str]:
        return [k for k, _ in self.events]

    def reached(self) -> list[object]:
        return [i for k, i in self.events if k == "waypoint_reached"]

    def fly_the_survey(self) -> None:
        """Take off on item 0, fly 2, 3, 4 (the speed change 1 is no navigation), start the RTL."""
        self.see(on(0))
        self.reach(1)
        for item in (2, 3, 4):
            self.see(on(item))
            self.reach(item + 1)
        self.see(on(5))


def test_the_survey_flown_item_by_item_finishes_once_when_its_rtl_starts():
    f = Flight()
    f.fly_the_survey()
    assert f.w.finished == "the last item (RTL) started"
    assert f.reached() == [0, 2, 3, 4] and f.kinds().count("mission_finished") == 1


@pytest.mark.parametrize("reported", [True, False])
def test_the_last_flights_end_after_the_upload_arming_and_start_is_not_this_ones(reported):
    """The issue's race: between the upload and the new mission's first MISSION_CURRENT the
    autopilot still says COMPLETE on the old last item, and the old item-reached comes again."""
    f = Flight(reported=reported)
    stale_current = replace(LIFT, **OLD_END)  # type: ignore[arg-type]
    f.see(stale_current)  # before the ack / right after it: the agent is still on the lift
    assert f.reach(6) == [False]
    armed = replace(stale_current, armed=True)
    f.see(armed)  # armed in GUIDED on the lift
    assert f.reach(6, 6) == [False, False]
    started = replace(FLYING, alt_rel=0.5, **OLD_END)  # type: ignore[arg-type]
    f.see(started, started)  # AUTO, armed: MISSION_START taken, the old end replayed again
    assert f.reach(6) == [False]
    assert f.w.finished is None and not f.w.started
    assert f.state.mission_state in ("NOT_STARTED", "ACTIVE")
    assert "mission_finished" not in f.kinds() and f.reached() == []
    f.fly_the_survey()  # then the new mission, which ends on its own
    assert f.reached() == [0, 2, 3, 4] and f.kinds().count("mission_finished") == 1
    assert f.w.ignored == 4  # the four old item-reached


def test_the_old_end_repeated_mid_flight_is_ignored():
    f = Flight()
    f.see(on(0))
    f.reach(1)
    f.see(on(2))
    assert f.reach(6) == [False]  # the old RTL's item-reached, late
    f.see(on(5, mission_state="COMPLETE"), on(2))  # the old MISSION_CURRENT, late, then ours
    assert f.w.finished is None and f.w.at == 2 and "mission_finished" not in f.kinds()


def test_a_mission_current_of_another_plan_is_set_aside_whole():
    f = Flight(opaque_id=0xBEEF)
    f.see(on(0, mission_id=0xBEEF))
    foreign = on(0, mission_id=0xDEAD, mission_state="COMPLETE")
    seen = f.see(foreign)
    assert seen.mission_id == 0xBEEF and seen.mission_state == "ACTIVE"
    assert f.w.finished is None and f.w.ignored == 1
    # the same plan uploaded again has the same id (a CRC32 of its items): the chain still rules
    f = Flight(opaque_id=0xBEEF)
    f.see(replace(FLYING, mission_id=0xBEEF, **OLD_END))  # type: ignore[arg-type]
    assert f.w.finished is None and "mission_finished" not in f.kinds()


def test_an_autopilot_without_mission_state_finishes_by_disarming_on_the_last_item_only_in_turn():
    """ArduPilot before 4.4: no mission_state, no id; the stale last item and a disarm (a failed
    start, disarmed again by the agent) are no end; the real last item and a disarm are."""
    commands = [22, 16, 16, 16]
    f = Flight(commands, reported=False)
    stale = replace(FLYING, alt_rel=0.0, mission_current=3, mission_state="UNKNOWN")
    f.see(stale, replace(stale, armed=False))
    assert f.w.finished is None
    for item in range(4):
        f.see(on(item, mission_state="UNKNOWN"))
        f.reach(item) if item else None
    f.see(on(3, mission_state="UNKNOWN", armed=False))
    assert f.w.finished == "disarmed in AUTO on the last item"


def test_leaving_auto_on_the_last_item_finishes_it_but_our_own_change_does_not():
    for own in (True, False):
        f = Flight([22, 16, 16, 16], reported=False)
        for item in range(4):
            f.see(on(item, mission_state="UNKNOWN"))
        if own:
            f.w.asked_mode(f.now)  # the agent paused it
        f.see(on(3, mode="LOITER", mission_state="UNKNOWN"))  # PX4: HOLD at a mission's end
        assert f.w.finished == (None if own else "left AUTO for LOITER on the last item")


def test_reaching_the_last_waypoint_in_turn_finishes_a_mission_ending_on_a_waypoint():
    f = Flight([22, 16, 16, 16, 183])  # ... DO_SET_SERVO after the last waypoint
    f.see(on(0))
    assert f.reach(1, 2, 3) == [True, True, True]  # each the next one: MISSION_CURRENT missed
    assert f.w.finished is None
    assert f.reach(4) == [True] and f.w.finished == "item 3, the last, reached"


def test_an_item_reached_out_of_turn_is_not_the_missions():
    f = Flight()
    f.see(on(0))
    assert f.reach(4) == [False]  # item 3 before item 2: not this flight's
    assert f.reach(1, 3) == [True, True] and f.reached() == [0, 2]


def test_a_final_land_item_starting_finishes_but_a_last_waypoint_or_an_earlier_rtl_does_not():
    f = Flight([22, 16, 16, 21])
    for item in range(4):
        f.see(on(item))
    assert f.w.finished == "the last item (LAND) started"
    f = Flight([22, 20, 16, 16])
    for item in range(4):
        f.see(on(item))
    assert f.w.finished is None


def test_the_autopilots_complete_is_believed_on_the_last_item_only():
    f = Flight([22, 16, 16])
    f.see(on(0), on(1, mission_state="COMPLETE"))
    assert f.w.finished is None and f.state.mission_state == "ACTIVE"
    f.see(on(2), on(2, mission_state="COMPLETE"))
    assert f.w.finished == "the autopilot reports it complete"


def test_our_own_rtl_on_the_way_to_the_last_waypoint_is_an_abort_not_the_end():
    f = Flight([22, 16, 16, 16])
    f.see(on(0), on(1), on(2))
    f.w.asked_mode(f.now)  # Autopilot.return_to_base
    f.see(on(2, mode="RTL", mission_state="NOT_STARTED"))
    assert f.w.finished is None


def test_finished_stays_finished_until_a_start_from_the_first_item_or_a_new_upload():
    f = Flight()
    f.fly_the_survey()
    rtl = on(5, mode="RTL", mission_state="NOT_STARTED")  # the run's RTL stops AP_Mission
    landed = replace(rtl, armed=False, alt_rel=0.0, landed_state="ON_GROUND")
    f.see(rtl, landed, replace(landed, mission_state="COMPLETE"))
    assert f.w.finished and f.kinds().count("mission_finished") == 1
    f.see(on(0))  # started again from its first item in AUTO: a new flight of the same mission
    assert f.w.finished is None and f.w.at == 0
    f.w.uploaded(6, SURVEY)
    assert f.w.finished is None and not f.w.started


def test_a_final_rtl_touching_down_is_reached_before_landed_and_the_late_report_is_a_repeat():
    """ArduPilot says the RTL item reached when its land detector has seen the ground for a
    second; the agent's landed state can say so first: no waypoint_reached after `landed`."""
    f = Flight()
    f.fly_the_survey()
    down = on(5, alt_rel=0.1, landed_state="ON_GROUND")
    f.see(on(5, landed_state="LANDING"), down)
    assert f.reach(6) == [False]  # the autopilot's own, a second later
    kinds = f.kinds()
    assert f.reached() == [0, 2, 3, 4, 5]
    assert kinds.index("landed") > max(i for i, k in enumerate(kinds) if k == "waypoint_reached")


def test_a_mission_adopted_in_flight_follows_the_item_the_autopilot_reports():
    w = MissionWatch()
    w.uploaded(6, SURVEY, adopted=True)
    w.on_change(on(3), on(3), 1.0)
    assert w.at == 3
    assert w.current_command() == 16
    _, ours = w.on_reached(on(3), 4)
    assert ours and w.at == 3


def test_once_an_item_is_reached_the_next_is_flown_before_its_mission_current_says_so():
    f = Flight()
    f.see(on(0))
    f.reach(1, 3, 4, 5)  # the last waypoint reached: the RTL item flies (landing inference, RTL)
    assert f.w.at == 4 and f.w.current_command() == 20 and f.w.finished is None
