"""When the uploaded mission is finished: its own end, never the last flight's.

Right after a flight, what a link says about "the mission" is partly the last one's: the autopilot
keeps the finished mission's state and current item across a new upload until MISSION_START runs
the new one, so MISSION_CURRENT says COMPLETE on the old last item between the upload and the
start; and a radio or a router that queues, retries or reorders hands over the old
MISSION_CURRENT and MISSION_ITEM_REACHED after the new upload and the arming, repeated, or before
the upload's MISSION_ACK (the simulator's `stale_mission` fault, sim/vehicle/stale.py). Taken at
their word they end a flight that has just taken off (issue 46: 3 of 6 runs went from flying to
"mission finished" within 0.5 s).

So `MissionWatch` follows the new mission as a chain of its navigation items (`at`):
- it starts only when the vehicle, armed in AUTO or having accepted the agent's MISSION_START
  (ArduPilot 3.x tells the arming and AUTO by its next 1 Hz HEARTBEAT only), reports the new
  mission's first navigation item (MISSION_CURRENT) or reaches it (MISSION_ITEM_REACHED): a
  demonstrated start;
- it moves on only to the next navigation item (MISSION_CURRENT naming it, or MISSION_ITEM_REACHED
  of it when its MISSION_CURRENT was missed: at 10x, 1 Hz MISSION_CURRENT skips items); an item
  further on, or the last one out of turn, is the old mission talking and is ignored; so is an
  earlier one (MISSION_CURRENT lags; a DO_JUMP loop comes back to the chain's item);
- where the autopilot names its plan (MISSION_CURRENT.mission_id against the upload's
  MISSION_ACK.opaque_id: ArduPilot 4.5+ and PX4 send a CRC32 of the stored items), a
  MISSION_CURRENT of another plan is ignored whole. The id is of the content: the same mission
  uploaded again has the same id, so it cannot tell this flight from the last flight of the
  same plan; the chain does (and autopilots that send no id, ArduPilot 3.x-4.4, have only it).

The mission counts as finished once (until the next upload, or a start again from its first item
in AUTO), and only with the chain on its last navigation item, when
- MISSION_ITEM_REACHED names that item in turn (ArduPilot sends it when the item is verified: a
  waypoint on arrival, a NAV_LAND / RTL item at touchdown, ModeAuto::verify_RTL), or
- that item starts (MISSION_CURRENT) and it is NAV_RETURN_TO_LAUNCH or NAV_LAND: the survey is
  over and the vehicle is heading home (ArduPilot reports COMPLETE only after the touchdown, and
  never if the run switches to RTL meanwhile: a mode change stops AP_Mission, whose
  MISSION_CURRENT.mission_state then reads NOT_STARTED), or
- MISSION_CURRENT.mission_state says COMPLETE (ArduPilot 4.4+, PX4 1.14+).
For autopilots that do not report mission_state (before ArduPilot 4.4) also when, on that item,
- the vehicle, in AUTO, disarms (a LAND / RTL last item ends on the ground), or
- the mode changes to a non-AUTO mode that the agent did not ask for in the previous
  `own_mode_change_s` (2 s) (PX4 switches to HOLD at the end of a mission).
Until then a COMPLETE the autopilot reports is not passed on (the state says ACTIVE or
NOT_STARTED), so no `mission_finished` event comes of it.

A final RTL / LAND item touching down is its MISSION_ITEM_REACHED, which ArduPilot sends when its
land detector has seen the ground for a second: `touched_down` reports it at the touchdown the
agent sees, before the `landed` event, and the autopilot's own, later, is then a repeat.
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from dataclasses import replace

from asset_agent.autopilot.flight_state import FINAL_COMMANDS, NAV_RETURN_TO_LAUNCH, home_distance_m
from asset_agent.autopilot.state import UavState

log = logging.getLogger(__name__)

NAV_COMMAND_MAX = 99  # MAV_CMD_NAV_* are 16..99; DO_* and CONDITION_* come after
HOME_RADIUS_M = 5.0  # a touchdown this near home ends a final RTL item


class MissionWatch:
    """Tells when the uploaded mission is finished, from whatever the autopilot sends (module
    docstring)."""

    def __init__(self, own_mode_change_s: float = 2.0) -> None:
        self.own_mode_change_s = own_mode_change_s
        self.reported = False  # the autopilot reports mission_state itself
        self.total: int | None = None  # items without home
        self.commands: list[int] = []  # the uploaded mission's MAV_CMDs, server index order
        self.opaque_id = 0  # the upload's MISSION_ACK.opaque_id (0: the autopilot gave none)
        self.finished: str | None = None  # why the mission counts as finished, once
        self.at: int | None = None  # the navigation item the new mission is known to fly
        self.reached_at = False  # its MISSION_ITEM_REACHED heard (or its touchdown seen)
        self.trust_current = False  # adopted in flight: the autopilot's item is this mission's
        self.commanded = False  # the autopilot accepted this agent's MISSION_START since the upload
        self.ignored = 0  # stale or foreign reports set aside (tests and logs read it)
        self._asked_mode_at = -1e9

    def uploaded(
        self,
        count: int,
        commands: Sequence[int] = (),
        opaque_id: int = 0,
        adopted: bool = False,
    ) -> None:
        """A mission of `count` items (home excluded) went up (MISSION_ACK `opaque_id`): a fresh
        mission, not started. `adopted`: found on the autopilot by an agent that started after
        the upload, perhaps in flight: the item it reports is this mission's."""
        self.total = count
        self.commands = list(commands)
        self.opaque_id = opaque_id
        self.finished = None
        self.at = None
        self.reached_at = False
        self.trust_current = adopted
        self.commanded = False

    def start_commanded(self) -> None:
        """The autopilot accepted MISSION_START (its COMMAND_ACK): what it says of the first item
        from now on is of this mission, whatever the HEARTBEAT has told yet."""
        self.commanded = True

    def asked_mode(self, now: float) -> None:
        """The agent itself changed the mode now."""
        self._asked_mode_at = now

    def command_at(self, index: int | None) -> int | None:
        """The MAV_CMD of item `index` (server numbering) of the uploaded mission, if known."""
        if index is None or not 0 <= index < len(self.commands):
            return None
        return self.commands[index]

    def _is_nav(self, index: int) -> bool:
        command = self.command_at(index)
        return command is None or command <= NAV_COMMAND_MAX

    def _nav_after(self, index: int | None) -> int | None:
        """The first navigation item after `index` (the first of all for None)."""
        start = 0 if index is None else index + 1
        for i in range(start, self.total or 0):
            if self._is_nav(i):
                return i
        return None

    def last_nav_index(self, total: int | None = None) -> int | None:
        """The index of the mission's last navigation item (its last item if commands unknown)."""
        for i in range(len(self.commands) - 1, -1, -1):
            if self.commands[i] <= NAV_COMMAND_MAX:
                return i
        total = self.total if total is None else total
        return total - 1 if total else None

    @property
    def started(self) -> bool:
        """The new mission has demonstrably started (module docstring)."""
        return self.at is not None

    def current_command(self) -> int | None:
        """The MAV_CMD of the item the mission is known to fly (None before its start): once an
        item is reached the autopilot flies the next one at once, though its MISSION_CURRENT (1 Hz)
        may not have said so yet."""
        flying = self.at
        if self.reached_at and self.at is not None and self.at != self.last_nav_index():
            flying = self._nav_after(self.at)
        return self.command_at(flying)

    def _ours(self, s: UavState) -> bool:
        """The state's MISSION_CURRENT is of the uploaded plan, as far as the ids tell."""
        return not self.opaque_id or not s.mission_id or s.mission_id == self.opaque_id

    def on_reached(self, s: UavState, seq: int) -> tuple[UavState, bool]:
        """MISSION_ITEM_REACHED(seq): the state after it and whether it is the mission's own (a
        `waypoint_reached`); the last navigation item reached in turn finishes the mission."""
        k = seq - 1
        if self.total is None:  # no mission known (an agent restarted before adopting it)
            return s, True
        flying = s.mode == "AUTO" and s.armed
        if k == self.at and not self.reached_at:
            self.reached_at = True
        elif k == self._nav_after(self.at) and (self.started or s.armed or self.commanded):
            # for the first item, armed or MISSION_START accepted is enough: ArduPilot 3.x tells
            # the arming and AUTO by its next 1 Hz HEARTBEAT only, after the take-off item may
            # already be reached at 10x
            self.at, self.reached_at = k, True
        elif self.at is not None and k < self.at and flying and self.finished is None:
            return s, True  # a DO_JUMP loop flies an earlier item again: reached, no progress
        else:
            self.ignored += 1
            log.info("MISSION_ITEM_REACHED %d ignored: not this mission's next item", seq)
            return s, False
        if k == self.last_nav_index():
            return self._finish(s, f"item {k}, the last, reached"), True
        return s, True

    def touched_down(self, prev: UavState, cur: UavState) -> int | None:
        """The final RTL / LAND item reached by this touchdown (its index), or None."""
        last = self.last_nav_index()
        if last is None or self.at != last or self.reached_at:
            return None
        if self.command_at(last) not in FINAL_COMMANDS:
            return None
        was_flying = prev.armed and prev.in_air
        if not was_flying or (cur.armed and cur.landed_state != "ON_GROUND"):
            return None
        home = home_distance_m(cur)
        if cur.mode != "AUTO" and (home is None or home > HOME_RADIUS_M):
            return None  # came down elsewhere (a failsafe's LAND): not the item's touchdown
        self.reached_at = True
        return last

    def on_change(self, prev: UavState, cur: UavState, now: float) -> UavState:
        """A new state from any message: the rules of the module docstring."""
        if not self._ours(cur):  # another plan's MISSION_CURRENT: what we knew stands
            self.ignored += 1
            cur = replace(
                cur,
                mission_current=prev.mission_current,
                mission_total=prev.mission_total,
                mission_state=prev.mission_state,
                mission_id=prev.mission_id,
            )
        last = self.last_nav_index(self.total if self.total is not None else cur.mission_total)
        if self.finished is not None:
            if not self._restarted(prev, cur):
                return replace(cur, mission_state="COMPLETE")
            self.finished, self.at, self.reached_at = None, None, False
        self._follow(cur)
        if last is not None and self.at == last:
            done = self._finished_now(prev, cur, last, now)
            if done:
                return self._finish(cur, done)
        if cur.mission_state == "COMPLETE":  # not this mission's end (yet): the last one's
            return replace(cur, mission_state="ACTIVE" if self.started else "NOT_STARTED")
        if cur.mode == "AUTO" and cur.armed and self.started:
            if cur.mission_state in ("UNKNOWN", "NOT_STARTED"):
                return replace(cur, mission_state="ACTIVE")
        return cur

    def _follow(self, cur: UavState) -> None:
        """Move the chain on with the item MISSION_CURRENT names, when it is the next one."""
        k = cur.mission_current
        flying = cur.mode == "AUTO" and cur.armed
        if k is None or k == self.at or not (flying or (self.commanded and self.at is None)):
            return
        if self.trust_current and self.at is None and 0 <= k < (self.total or 0):
            self.at, self.reached_at = k, False  # adopted in flight: where it is, it is
            return
        if k == self._nav_after(self.at):
            self.at, self.reached_at = k, False

    def _restarted(self, prev: UavState, cur: UavState) -> bool:
        """Started again from its first item in AUTO after it finished: a new flight of it."""
        first = self._nav_after(None)
        return (
            cur.mode == "AUTO"
            and cur.armed
            and first is not None
            and cur.mission_current == first
            and prev.mission_current != first
            and self._ours(cur)
        )

    def _finished_now(self, prev: UavState, cur: UavState, last: int, now: float) -> str:
        """Why the mission is over now that the chain is on its last item ("" if it is not)."""
        if cur.mission_state == "COMPLETE":
            return "the autopilot reports it complete"
        command = self.command_at(last)
        if cur.mode == "AUTO" and cur.armed and cur.mission_current == last:
            if command in FINAL_COMMANDS:
                name = "RTL" if command == NAV_RETURN_TO_LAUNCH else "LAND"
                return f"the last item ({name}) started"
        if self.reported or prev.mode != "AUTO" or prev.mission_current != last:
            return ""
        if prev.armed and not cur.armed:
            return "disarmed in AUTO on the last item"
        own = now - self._asked_mode_at < self.own_mode_change_s
        if cur.mode not in ("AUTO", "UNKNOWN") and not own:
            return f"left AUTO for {cur.mode} on the last item"
        return ""

    def _finish(self, s: UavState, why: str) -> UavState:
        if self.finished is None:
            self.finished = why
            log.info("mission finished: %s", why)
        return replace(s, mission_state="COMPLETE")
