"""The base's commands that move nothing: charging (start, stop) and the availability check,
for the `Station` facade (station.py), which replies through its `reject` and `fail`."""

from __future__ import annotations

import time
from collections.abc import AsyncIterator, Callable

from base_station.availability import availability
from base_station.config import StationConfig
from base_station.coordinator import Coordinator
from base_station.devices.charger import charger_idle_reason, check_start_charging
from base_station.outcomes import Item, Progress, Result, Status
from base_station.plc import ChargerState, Coil, HoldingRegister
from protocol.vocabulary import CheckAvailability, CommandParams, StartCharging

Reply = Callable[[str, str], Result]


class ChargingCommands:
    """start_charging, stop_charging and check_availability against the coordinator's PLC."""

    def __init__(
        self, coordinator: Coordinator, config: StationConfig, reject: Reply, fail: Reply
    ) -> None:
        self.coord = coordinator
        self.config = config
        self.reject = reject  # a refusal, reported as an event too
        self.fail = fail

    async def start(self, command: StartCharging) -> AsyncIterator[Item]:
        name = command.name
        limit = command.current_limit_ma
        if limit is None:
            limit = self.config.charge.current_limit_ma
        snap = self.coord.snapshot
        decision = check_start_charging(snap.plc, snap.link_up)
        if not decision.allowed:
            yield self.reject(name, decision.reason)
            return
        await self.coord.write_register(HoldingRegister.CHARGE_CURRENT_LIMIT, limit)
        written = await self.coord.write_coil(Coil.CHARGER_ENABLE, True)
        yield Progress(name, "charger_enabled", f"charger enabled, limit {limit} mA")
        window = self.config.charge.start_timeout_s
        deadline = written + window
        snap = await self.coord.wait_fresh(written)
        while True:
            plc = snap.plc
            if (
                snap.link_up
                and plc is not None
                and plc.charger_state in (ChargerState.CHARGING, ChargerState.COMPLETE)
            ):
                yield Result(
                    name,
                    Status.SUCCEEDED,
                    f"charger {plc.charger_state.name.lower()}",
                    {
                        "current_ma": plc.charge_current_ma,
                        "uav_battery_pct": plc.uav_battery_soc_pct,
                    },
                )
                return
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                break
            # a strictly newer poll, awaited: re-reading the same snapshot would spin the loop
            snap = await self.coord.wait_next(snap.seq, remaining)
        yield self.fail(
            name,
            f"charger did not start within {window:g} s: "
            + charger_idle_reason(snap.plc, snap.link_up),
        )

    async def stop(self, command: CommandParams) -> AsyncIterator[Item]:
        name = command.name
        if not self.coord.snapshot.link_up:
            yield self.fail(name, "PLC link down")
            return
        await self.coord.write_coil(Coil.CHARGER_ENABLE, False)
        yield Result(name, Status.SUCCEEDED, "charger disabled")

    async def check_availability(self, command: CheckAvailability) -> AsyncIterator[Item]:
        # mass_g / mass_window_g are typed but unused: the UAV window comes from config.uav
        name = command.name
        report = availability(self.coord.snapshot, self.config)
        data = report.model_dump(mode="json")
        if not report.available:
            yield Result(name, Status.REJECTED, "not available: " + report.summary, data)
        else:
            yield Result(name, Status.SUCCEEDED, "available", data)
