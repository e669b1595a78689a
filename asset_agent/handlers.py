"""The agent's commands: thin async handlers from protocol commands to the autopilot adapter."""

from __future__ import annotations

from collections.abc import AsyncIterator
from dataclasses import asdict
from typing import Any

from asset_agent.autopilot import (
    Autopilot,
    AutopilotError,
    CommandRejected,
    InvalidMissionItem,
    items_from_dicts,
)
from asset_agent.availability import AvailabilityLimits, check_availability
from assetlink.dispatch import CommandRequest, result
from protocol.messages import CommandProgress, CommandResultPayload


def _failure(err: AutopilotError) -> CommandResultPayload:
    return result("rejected" if isinstance(err, CommandRejected) else "failed", str(err))


class Handlers:
    """Every command the agent answers, bound to one autopilot."""

    def __init__(self, autopilot: Autopilot, limits: AvailabilityLimits) -> None:
        self.autopilot = autopilot
        self.limits = limits

    def table(self) -> dict[str, Any]:
        """Command name -> handler, for `Link.on_command`."""
        return {
            "check_availability": self.check_availability,
            "upload_mission": self.upload_mission,
            "start_mission": self.start_mission,
            "pause": self.simple("pause"),
            "resume": self.simple("resume"),
            "return_to_base": self.simple("return_to_base"),
            "land": self.simple("land"),
            "abort": self.abort,
        }

    async def check_availability(self, request: CommandRequest) -> CommandResultPayload:
        """Battery, GNSS fix, autopilot health and link, disarmed: every failed condition listed."""
        failed = check_availability(self.autopilot.state, self.limits)
        conditions = [{**asdict(f), "value": f.value, "limit": f.limit} for f in failed]
        if failed:
            return result("failed", "; ".join(f.message for f in failed), {"failed": conditions})
        s = self.autopilot.state
        return result(
            "succeeded",
            "available",
            {"failed": [], "battery_pct": s.battery_pct, "fix": s.fix_name},
        )

    async def upload_mission(
        self, request: CommandRequest
    ) -> AsyncIterator[CommandProgress | CommandResultPayload]:
        """Upload the items, read them back and compare."""
        raw = request.params.get("items")
        if not isinstance(raw, list) or not raw:
            yield result("rejected", "upload_mission needs a non-empty list `items`")
            return
        try:
            items = items_from_dicts(raw)
        except InvalidMissionItem as err:
            yield result("rejected", str(err))
            return
        yield CommandProgress(
            step="upload", index=1, total=2, message=f"uploading {len(items)} items"
        )
        try:
            await self.autopilot.upload_mission(items, verify=True)
        except AutopilotError as err:
            yield _failure(err)
            return
        yield CommandProgress(step="verify", index=2, total=2, message="read back and identical")
        yield result(
            "succeeded", f"{len(items)} items uploaded and verified", {"count": len(items)}
        )

    async def start_mission(self, request: CommandRequest) -> CommandResultPayload:
        """Arm and start the uploaded mission (AUTO)."""
        try:
            await self.autopilot.start_mission()
        except AutopilotError as err:
            return _failure(err)
        return result("succeeded", "mission started")

    def simple(self, name: str):  # type: ignore[no-untyped-def]
        """A handler calling one autopilot method without arguments."""

        async def handler(request: CommandRequest) -> CommandResultPayload:
            try:
                await getattr(self.autopilot, name)()
            except AutopilotError as err:
                return _failure(err)
            return result("succeeded", name.replace("_", " "))

        return handler

    async def abort(self, request: CommandRequest) -> CommandResultPayload:
        """Return to the base when flying, disarm when on the ground."""
        try:
            done = await self.autopilot.abort()
        except AutopilotError as err:
            return _failure(err)
        return result(
            "succeeded", "returning to the base" if done == "rtl" else "disarmed", {"action": done}
        )
