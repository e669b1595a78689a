"""The agent's commands: thin async handlers from typed protocol commands to the autopilot.

`return_to_base` knows the agent owns the landing: a server that lost the UAV mid-flight (killed,
or the link cut) asks for it when the link returns, after the mission's own return-home has
already brought the UAV back (precision landing runs in the agent, server or not). Re-commanding
RTL then would climb a landing UAV back to RTL altitude for a second approach, or leave a landed
one in RTL mode; so it answers what is already happening instead.
"""

from __future__ import annotations

import asyncio
import logging
from collections.abc import AsyncIterator, Awaitable, Callable, Sequence
from typing import Any

from asset_agent.autopilot import (
    Autopilot,
    AutopilotError,
    CommandRejected,
    InvalidMissionItem,
    items_from_dicts,
)
from asset_agent.availability import AvailabilityLimits, report
from assetlink.dispatch import CommandRequest, Handler, result
from protocol.messages import CommandProgress, CommandResultPayload
from protocol.vocabulary import (
    Abort,
    AvailabilityCondition,
    CheckAvailability,
    CommandParams,
    Land,
    Pause,
    Resume,
    ReturnToBase,
    StartMission,
    UploadMission,
)

NAV_RETURN_TO_LAUNCH = 20
RETURNING_MODES = ("RTL", "SMART_RTL")

log = logging.getLogger(__name__)


def _failure(err: AutopilotError) -> CommandResultPayload:
    return result("rejected" if isinstance(err, CommandRejected) else "failed", str(err))


class Handlers:
    """Every command the agent answers, bound to one autopilot."""

    def __init__(
        self,
        autopilot: Autopilot,
        limits: AvailabilityLimits,
        checks: Sequence[Callable[[], Awaitable[AvailabilityCondition]]] = (),
    ) -> None:
        """`checks`: conditions read from the autopilot at each availability check."""
        self.autopilot = autopilot
        self.limits = limits
        self.checks = tuple(checks)

    def table(self) -> dict[type[CommandParams], Handler]:
        """Command type -> handler, for `Link.on_command`."""
        return {
            CheckAvailability: self.check_availability,
            UploadMission: self.upload_mission,
            StartMission: self.start_mission,
            Pause: self.simple(self.autopilot.pause),
            Resume: self.simple(self.autopilot.resume),
            ReturnToBase: self.return_to_base,
            Land: self.simple(self.autopilot.land),
            Abort: self.abort,
        }

    async def check_availability(
        self, request: CommandRequest[CheckAvailability]
    ) -> CommandResultPayload:
        """Battery, GNSS fix, autopilot health and link, disarmed, and `checks` (read from the
        autopilot now): every failed condition listed."""
        more = [await check() for check in self.checks]
        answer = report(self.autopilot.state, self.limits, more)
        data = answer.model_dump(mode="json")
        if not answer.available:
            return result("failed", answer.summary, data)
        return result("succeeded", "available", data)

    async def upload_mission(
        self, request: CommandRequest[UploadMission]
    ) -> AsyncIterator[CommandProgress | CommandResultPayload]:
        """Upload the items, read them back and compare what the autopilot keeps (autopilot/verify.py);
        with a fence, upload it and the rally points the same way and enable the fence (RTL)."""
        cmd = request.command
        try:
            items = items_from_dicts([i.model_dump() for i in cmd.items])
            fence = items_from_dicts([i.model_dump() for i in cmd.fence or ()])
            rally = items_from_dicts([i.model_dump() for i in cmd.rally])
        except InvalidMissionItem as err:
            yield result("rejected", str(err))
            return
        total = 2 if cmd.fence is None else 4
        yield CommandProgress(
            step="upload", index=1, total=total, message=f"uploading {len(items)} items"
        )
        try:
            await self.autopilot.upload_mission(items, verify=True)
        except AutopilotError as err:
            yield _failure(err)
            return
        yield CommandProgress(
            step="verify",
            index=2,
            total=total,
            message="read back: as sent, as far as the autopilot keeps it",
        )
        data: dict[str, Any] = {"count": len(items)}
        if cmd.fence is not None:
            yield CommandProgress(
                step="fence",
                index=3,
                total=total,
                message=f"uploading a fence of {len(fence)} items and {len(rally)} rally points",
            )
            try:
                data |= await self._fence(cmd, fence, rally, total)
            except AutopilotError as err:
                yield _failure(err)
                return
            yield CommandProgress(
                step="fence", index=4, total=total, message="fence read back and enabled"
            )
        what = f"{len(items)} items uploaded and verified"
        if cmd.fence is not None:
            what += f"; fence of {len(fence)} items and {len(rally)} rally points verified"
            what += ", fence enabled" if fence else ""
        yield result("succeeded", what, data)

    async def _fence(
        self, cmd: UploadMission, fence: list[Any], rally: list[Any], total: int
    ) -> dict[str, Any]:
        """Fence and rally points uploaded and read back, then the fence enabled (when any)."""
        await self.autopilot.upload_fence(fence, rally)
        out: dict[str, Any] = {"fence_items": len(fence), "rally_points": len(rally)}
        if fence:
            out["fence_params"] = await self.autopilot.enable_fence(cmd.fence_alt_max_m)
        return out

    async def start_mission(self, request: CommandRequest[StartMission]) -> CommandResultPayload:
        """Arm and start the uploaded mission (AUTO)."""
        try:
            await self.autopilot.start_mission()
        except AutopilotError as err:
            return _failure(err)
        return result("succeeded", "mission started")

    async def _where_the_mission_is(self) -> None:
        """Asked at once by a server that queued the command while this agent was away (a
        restart), before the agent has heard its autopilot, read the mission off it (main.py) or
        heard which item it flies: wait for each, a few seconds at most; what is still unknown
        then leaves an RTL, the safe side. Otherwise an RTL lands on the mission's own."""
        ap = self.autopilot
        bound = ap.config.link_timeout_s
        try:
            if not ap.link_up:
                await ap.wait_link(bound)
            if not (ap.state.armed and ap.state.mode == "AUTO"):
                return
            if ap.mission_watch.total is None:
                await ap.adopt_mission()
            if ap.state.mission_current is None:
                with ap.tap(lambda m: m.get_type() == "MISSION_CURRENT") as heard:
                    await asyncio.wait_for(heard.get(), bound)
        except (AutopilotError, TimeoutError) as err:
            log.warning(
                "where the mission is could not be read: %s", str(err) or "no MISSION_CURRENT"
            )

    def already_home(self) -> str:
        """Why a return to the base has nothing to do ("" when it has): the UAV has landed, or
        is already on its way (RTL, or the mission's own return-home item in AUTO)."""
        s = self.autopilot.state
        if not s.armed and s.landed_state == "ON_GROUND":
            return "already landed: nothing to return from"
        if not s.armed:
            return ""
        if s.mode in RETURNING_MODES:
            return f"already returning to the base ({s.mode})"
        # the item of the mission this agent uploaded (or found on the autopilot when it
        # started) that it is known to fly: not a stale MISSION_CURRENT of the last flight's
        command = self.autopilot.mission_watch.current_command()
        if s.mode == "AUTO" and command == NAV_RETURN_TO_LAUNCH:
            return "already returning to the base: the mission's own return-home"
        return ""

    async def return_to_base(self, request: CommandRequest[ReturnToBase]) -> CommandResultPayload:
        """RTL, unless the UAV is already back or on its way (then it is left to land as it is)."""
        await self._where_the_mission_is()
        why = self.already_home()
        if why:
            return result("succeeded", why, {"action": "none"})
        try:
            await self.autopilot.return_to_base()
        except AutopilotError as err:
            return _failure(err)
        return result("succeeded", "return to base", {"action": "rtl"})

    def simple(self, method: Callable[[], Awaitable[object]]) -> Handler:
        """A handler calling one autopilot method without arguments."""

        async def handler(request: CommandRequest[CommandParams]) -> CommandResultPayload:
            try:
                await method()
            except AutopilotError as err:
                return _failure(err)
            return result("succeeded", request.name.replace("_", " "))

        return handler

    async def abort(self, request: CommandRequest[Abort]) -> CommandResultPayload:
        """Return to the base when flying, disarm when on the ground."""
        try:
            done = await self.autopilot.abort()
        except AutopilotError as err:
            return _failure(err)
        return result(
            "succeeded", "returning to the base" if done == "rtl" else "disarmed", {"action": done}
        )
