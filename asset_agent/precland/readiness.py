"""Will the autopilot land on our LANDING_TARGETs? A condition of the UAV's availability check.

In mode `landing_target` the autopilot's own precision landing flies the descent. ArduPilot
hands a LANDING_TARGET to it only when PLND_ENABLED is 1 and PLND_TYPE is 1 (companion computer);
both default to 0, and then the message is dropped without a word and LAND comes down on GNSS
alone, wherever that puts it (153 cm off from a 1.5 m offset, ../shared/notes). So before a run
the agent reads both: switched off, or another sensor type, the UAV is not available and the
message says what to set. An autopilot that answers no PLND_ENABLED has no ArduPilot precision
landing (PX4 has its own landing-target estimator, other parameters): nothing to check, said so.
"""

from __future__ import annotations

import logging
from collections.abc import Awaitable, Callable
from typing import Any

from asset_agent.autopilot.client import Autopilot
from asset_agent.autopilot.errors import AutopilotError
from asset_agent.autopilot.params import NoSuchParam, read_param, unanswered
from asset_agent.precland.config import AutopilotDescentConfig
from asset_agent.precland.restore import ParamLedger
from protocol.vocabulary import AvailabilityCondition

log = logging.getLogger(__name__)

NAME = "precision_landing"
PLND_TYPE_COMPANION = 1  # AC_PrecLand::Type::COMPANION (MAVLink LANDING_TARGET)
WHAT_TO_SET = (
    "set PLND_ENABLED = 1 and PLND_TYPE = 1 on the autopilot (and reboot it), or [precland] mode = "
    '"companion" to steer the descent from the agent'
)


class PrecisionLandingCheck:
    """Reads PLND_ENABLED and PLND_TYPE at each check. An autopilot that answered no
    PLND_ENABLED is not asked again until it reboots (`unanswered`: each silent read costs the
    adapter's retries). ArduPilot builds its PLND backend from PLND_TYPE at boot
    (AC_PrecLand::init), hence "and reboot it"."""

    def __init__(self, autopilot: Autopilot) -> None:
        self.autopilot = autopilot

    async def __call__(self) -> AvailabilityCondition:
        if unanswered(self.autopilot, "PLND_ENABLED"):
            return _no_plnd()
        try:
            enabled = await read_param(self.autopilot, "PLND_ENABLED")
        except NoSuchParam as exc:
            log.info("precland: the autopilot answers no PLND_ENABLED: %s", exc)
            return _no_plnd()
        except AutopilotError as exc:  # no link: autopilot_link says so; ask next time
            return AvailabilityCondition(
                name=NAME, ok=False, message=f"PLND_ENABLED not read: {exc}"
            )
        if enabled != 1:
            return AvailabilityCondition(
                name=NAME, ok=False, value=f"PLND_ENABLED={enabled:g}", limit="PLND_ENABLED=1",
                message="the autopilot's precision landing is off (PLND_ENABLED = "
                f"{enabled:g}): it would drop our LANDING_TARGETs and land on GNSS alone; "
                + WHAT_TO_SET,
            )  # fmt: skip
        try:
            kind = await read_param(self.autopilot, "PLND_TYPE")
        except AutopilotError as exc:
            return AvailabilityCondition(
                name=NAME, ok=False, message=f"PLND_TYPE not read: {exc}; {WHAT_TO_SET}"
            )
        if kind != PLND_TYPE_COMPANION:
            return AvailabilityCondition(
                name=NAME, ok=False, value=f"PLND_TYPE={kind:g}", limit="PLND_TYPE=1",
                message=f"the autopilot's precision landing reads another sensor (PLND_TYPE = "
                f"{kind:g}), not our LANDING_TARGETs; {WHAT_TO_SET}",
            )  # fmt: skip
        return AvailabilityCondition(
            name=NAME, ok=True, value="PLND_ENABLED=1 PLND_TYPE=1", limit="PLND_TYPE=1",
            message="the autopilot lands on our LANDING_TARGETs (PLND_ENABLED = 1, PLND_TYPE = 1)",
        )  # fmt: skip


def _no_plnd() -> AvailabilityCondition:
    return AvailabilityCondition(
        name=NAME, ok=True, value=None, limit=None,
        message="the autopilot has no PLND_ENABLED (not ArduPilot's precision landing): "
        "LANDING_TARGETs go to its own estimator, not checked here",
    )  # fmt: skip


async def descent_gate(
    autopilot: Any,
    ledger: ParamLedger,
    cfg: AutopilotDescentConfig,
    now: Callable[[], float],
    sleep: Callable[[float], Awaitable[None]],
    confirmed: Callable[[float], None],
) -> None:
    """PLND_XY_DIST_MAX for one landing: the configured radius (LAND descends only while its
    target estimate is that close), relaxed once the landing is `relax_after_s` old (`now` and
    `sleep` in the sensors' seconds); `confirmed` hears each value the autopilot holds. Set
    through `ledger`, which gives the value from before back when the landing ends (restore.py).
    An autopilot without the parameter (ArduPilot 3.x, PX4) is asked once per boot."""
    if unanswered(autopilot, "PLND_XY_DIST_MAX"):
        log.info("precland: the autopilot has no PLND_XY_DIST_MAX, LAND descends as it will")
        return
    start = now()
    try:
        for wait in (0.0, cfg.relax_after_s):
            await sleep(wait)
            value = cfg.xy_dist_max_at(now() - start)
            if value is not None:
                confirmed(await ledger.change("PLND_XY_DIST_MAX", value))
                log.info("precland: the autopilot holds PLND_XY_DIST_MAX %.2f m", value)
    except AutopilotError as exc:  # PX4, ArduPilot 3.x, or the link went: its own default
        log.warning("precland: PLND_XY_DIST_MAX not set, LAND descends as it will: %s", exc)
