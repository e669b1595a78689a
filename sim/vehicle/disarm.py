"""ArduPilot Copter's auto-disarm: a vehicle left armed on the ground disarms itself.

As `Copter::auto_disarm_check` (ArduCopter/motors.cpp, 4.x): armed, its land detector's
`land_complete` set, the throttle at zero (no pilot stick on a companion-flown vehicle) and the
motors not spooled above ground idle, for `DISARM_DELAY` seconds (default 10; 0: never) — then
it disarms. Spooled above ground idle here: a takeoff under way, or a mission flying in AUTO;
GUIDED on the ground flies no other target (ModeGuided's `is_disarmed_or_landed`), so armed
there without a takeoff it idles, and disarms. The timer starts again at every arming.

The delay is counted in wall seconds, as the simulator's protocol timers are: it is the time a
companion has between arming and its takeoff command, and a companion's latencies are wall
time whatever the simulation's speed (at 20x, ten simulated seconds would be half a second).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from sim.vehicle.constants import AUTO, MISSION_ACTIVE, ON_GROUND

if TYPE_CHECKING:
    from sim.vehicle.guidance import Guidance


def auto_disarm(g: Guidance) -> bool:
    """Start, keep or stop `g`'s vehicle's idle timer; disarm it when the timer runs out."""
    c = g.c
    flying_mission = c.mode == AUTO and g.mission_state == MISSION_ACTIVE
    if not (c.armed and g.landed_state() == ON_GROUND and not flying_mission):
        g.idle_since = None
        return False
    if g.idle_since is None:
        g.idle_since = c.wall
    delay = c.param("DISARM_DELAY")
    if delay <= 0 or c.wall - g.idle_since < delay:
        return False
    g.idle_since = None
    c.disarm()
    return True
