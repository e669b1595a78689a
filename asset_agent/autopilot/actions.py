"""The flight actions of the autopilot adapter: modes, arming, take-off, mission start, RTL, land, abort."""

from __future__ import annotations

import contextlib
import time
from collections.abc import Awaitable, Callable

from asset_agent.autopilot.errors import AutopilotError
from asset_agent.autopilot.mission_watch import MissionWatch
from asset_agent.autopilot.state import COPTER_MODES, MODE_NUMBERS, UavState

# MAV_CMD numbers
CMD_NAV_RETURN_TO_LAUNCH, CMD_NAV_LAND, CMD_NAV_TAKEOFF = 20, 21, 22
CMD_DO_SET_MODE, CMD_MISSION_START, CMD_COMPONENT_ARM_DISARM = 176, 300, 400
CMD_PREFLIGHT_REBOOT_SHUTDOWN = 246
FORCE_MAGIC = 21196


class ActionsMixin:
    """Actions of `Autopilot`; the host provides `state`, `mission_watch` and `command`."""

    state: UavState
    mission_watch: MissionWatch
    # the last mode change sent through this adapter that the autopilot took: when
    # (time.monotonic(), once its COMMAND_ACK was handled) and into which mode; whoever holds the
    # vehicle can tell another's command from its own
    mode_changed: tuple[float, str] = (float("-inf"), "")

    command: Callable[..., Awaitable[int]]  # COMMAND_LONG awaiting its ACK (Autopilot.command)

    async def set_mode(self, mode: str | int) -> None:
        """Change the flight mode by Copter name ("GUIDED") or number."""
        number = MODE_NUMBERS[mode.upper()] if isinstance(mode, str) else int(mode)
        name = COPTER_MODES.get(number, str(number))
        await self._into_mode(name, CMD_DO_SET_MODE, 1, number)  # CUSTOM_MODE_ENABLED

    async def _into_mode(self, mode: str, command: int, *params: float) -> None:
        """A command that changes the mode: our own change to MissionWatch, and `mode_changed`
        once the autopilot has taken it."""
        self.mission_watch.asked_mode(time.monotonic())
        await self.command(command, *params)
        self.mode_changed = (time.monotonic(), mode)

    async def arm(self) -> None:
        """Arm (pre-arm checks apply: a failure raises CommandRejected with the PreArm text)."""
        await self.command(CMD_COMPONENT_ARM_DISARM, 1)

    async def disarm(self, force: bool = False) -> None:
        """Disarm; the autopilot refuses in flight unless forced."""
        await self.command(CMD_COMPONENT_ARM_DISARM, 0, FORCE_MAGIC if force else 0)

    async def takeoff(self, alt_m: float) -> None:
        """GUIDED takeoff to `alt_m` above home (the vehicle must be armed in GUIDED)."""
        await self.command(CMD_NAV_TAKEOFF, 0, 0, 0, 0, 0, 0, alt_m)

    async def start_mission(self) -> None:
        """Start the uploaded mission: from the ground GUIDED + arm + MISSION_START; in the air AUTO.

        A start that fails after arming disarms again (the error is raised all the same): the
        motors would idle on the pad until the autopilot's DISARM_DELAY, 10 s on ArduPilot."""
        if self.state.armed and self.state.in_air:
            await self.set_mode("AUTO")
            return
        armed_here = not self.state.armed
        if armed_here:
            await self.set_mode("GUIDED")
            await self.arm()
        try:
            await self.command(CMD_MISSION_START, 0, 0)
            self.mission_watch.start_commanded()  # its first item is this mission's start
            self.mode_changed = (time.monotonic(), "AUTO")
        except AutopilotError:
            if armed_here:
                with contextlib.suppress(AutopilotError):  # a lost link: the delay disarms it
                    await self.disarm()
            raise

    async def pause(self, mode: str = "BRAKE") -> None:
        """Stop and hold position (BRAKE, or LOITER)."""
        await self.set_mode(mode)

    async def resume(self) -> None:
        """Resume the mission where it stopped (AUTO)."""
        await self.set_mode("AUTO")

    async def return_to_base(self) -> None:
        """Return to launch (the base) and land there (RTL mode: our own mode change)."""
        await self._into_mode("RTL", CMD_NAV_RETURN_TO_LAUNCH)

    async def land(self) -> None:
        """Land where the vehicle is (LAND mode: our own mode change)."""
        await self._into_mode("LAND", CMD_NAV_LAND)

    async def abort(self) -> str:
        """RTL when flying, disarm when on the ground; returns what was done."""
        if self.state.armed and self.state.landed_state != "ON_GROUND":
            await self.return_to_base()
            return "rtl"
        await self.disarm()
        return "disarmed"

    async def reboot(self) -> None:
        """MAV_CMD_PREFLIGHT_REBOOT_SHUTDOWN: restart the autopilot (refused while armed)."""
        await self.command(CMD_PREFLIGHT_REBOOT_SHUTDOWN, 1)
