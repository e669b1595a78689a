"""An agent restarted while it flew a landing itself (takeover.py: the search, the RTK fallback or
the guard's retry, all in GUIDED), as a crash and its service manager's restart leave it.

Once its velocity setpoints stop, ArduPilot holds a GUIDED vehicle where it is (PX4's offboard
mode falls back to its own failsafe). A new agent that did not know the hover was its
predecessor's landing would leave it there until the battery failsafe, the run would fail by its
landing budget and the base stay open. So the takeover is kept in the daemon's state file (the
link's key/values, `Memory`), committed before the agent takes the vehicle and changed when it
hands it back or gives the landing up:

| kept | meaning | a new agent that first finds the vehicle armed in the air in GUIDED |
|---|---|---|
| `flying` | the agent holds the vehicle for a landing | hands the descent back (LAND): the landing starts afresh, with the search, the fallback and the guard as before ("resume") |
| `holding` | the landing was abandoned (`landing_aborted`, already reported) and the vehicle holds at a safe height | leaves the hold to the operator ("hold") |
| none | the agent does not hold the vehicle | leaves it: a GUIDED vehicle is someone else's, a pilot's ground station ("none") |

What the new agent first finds decides, once. A resumed landing stays kept as flying until its
own takeover changes that (or, never taken, until the disarm); a vehicle found in any other state
has moved on, and what was kept is forgotten. A disarm forgets it too.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Literal, Protocol

KEY = "precland.takeover"
FLYING, HOLDING = "flying", "holding"

Decision = Literal["resume", "hold", "none"]


class Memory(Protocol):
    """Durable key/values that outlive the daemon (assetlink.link.Link)."""

    async def recall(self, key: str) -> str | None: ...

    async def remember(self, key: str, value: str | None) -> None: ...


def decide(left: str | None, state: Any) -> Decision:
    """What a restarted agent does with the vehicle it first finds, given what its predecessor
    left kept."""
    if left is None or not (state.armed and state.in_air and state.mode == "GUIDED"):
        return "none"
    return "resume" if left == FLYING else "hold"


def known(state: Any) -> bool:
    """The vehicle's state is known enough to decide: a HEARTBEAT (mode, armed) and its landed
    state (EXTENDED_SYS_STATE, or inferred: autopilot/flight_state.py)."""
    return bool(state.link_up and state.mode_known and state.landed_known)


@dataclass
class TakeoverRecord:
    """The takeover as kept in the state file: what this agent keeps now (`current`) and what the
    agent before it left (`left`, read once by `load`)."""

    memory: Memory | None = None
    left: str | None = None
    current: str | None = None
    decision: Decision | None = None  # taken at first sight

    async def load(self) -> None:
        """Read what the agent before this one left."""
        if self.memory is not None:
            self.left = self.current = await self.memory.recall(KEY)

    async def keep(self, value: str | None) -> None:
        """Keep `value` (FLYING, HOLDING or None), committed when this returns."""
        if self.memory is not None and value != self.current:
            await self.memory.remember(KEY, value)
        self.current = value

    def first_sight(self, state: Any) -> Decision | None:
        """The decision, once, as soon as the vehicle's state is known; None before and after."""
        if self.decision is not None or not known(state):
            return None
        self.decision = decide(self.left, state)
        return self.decision
