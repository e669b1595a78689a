"""Issue 14 #4: the base daemon killed while the panels open, restarted; the run ends with the base
closed or with an alert, and its reason says which.

The base daemon runs as its own process (`aerobase base-station`) and is SIGKILLed while the run
opens the base; the simulated PLC, served over Modbus TCP, latches its watchdog fault 2 s later as
the spec says (tests/sim/test_plc_model.py checks that it does). The restarted daemon clears that
latch, the run's interrupted `open` fails it, and the close issued on the way out closes the base.
"""

from __future__ import annotations

import asyncio
from typing import Any

import pytest

from tests.conftest import Tenant
from tests.e2e.harness import FINAL, platform
from tests.polling import eventually

pytestmark = pytest.mark.slow  # whole processes end to end: not in the fast lane

SETTLED = ("safe_state_reached", "safe_state_not_reached")
BEING_CLOSED = "the base is being closed"  # what the run says when it issues the close


async def settled(p: Any, run_id: str, limit_s: float = 60) -> dict[str, Any]:
    """The run once what became of its close on the way out is recorded."""

    async def verdict() -> dict[str, Any] | None:
        body = await p.run_state(run_id)
        return body if body["timeline"] and body["timeline"][-1]["cause"] in SETTLED else None

    return dict(await eventually(verdict, limit_s, "the run to record whether the base closed"))


async def test_base_daemon_killed_mid_open_restarts_recovers_the_plc_and_the_run_closes_the_base(
    live_server, tenant: Tenant, tmp_path
):
    async with platform(live_server.url, tenant, tmp_path, speed=4.0, base_process=True) as p:
        base, daemon = p.world.base, p.base_daemon
        assert daemon is not None
        run_id = await p.start_run()
        await p.wait_state(run_id, ("opening",), 60)
        await eventually(lambda: base.panels.position >= 0.3, 30, "the panels 30 % open")
        await asyncio.to_thread(daemon.kill)
        killed_at = base.panels.position
        await eventually(lambda: base.fault_bits() & 16, 10, "the PLC to latch its watchdog")
        assert not base.panels.moving, base.ground_truth()
        await asyncio.to_thread(daemon.start)
        body = await p.wait_state(run_id, FINAL, 90)
        assert body["state"] == "failed" and body["cause"] == "opening_failed", body["reason"]
        body = await settled(p, run_id)
        note = body["timeline"][-1]
        assert note["cause"] == "safe_state_reached", (note, daemon.output()[-3000:])
        assert base.panels.at_low and base.lift.at_low, (killed_at, base.ground_truth())
        assert base.fault_bits() & 16 == 0
        assert "the base is closed" in body["reason"] and BEING_CLOSED not in body["reason"]
        assert not body["alert"], body["reason"]
        coils = [c.coil for c in base.command_log]
        assert "FAULT_RESET" in coils and "LIFT_UP" not in coils, coils
    # it logged in twice; its log tells what it did, not each HTTP call (httpx: INFO a call)
    assert "logged in" in daemon.output() and "HTTP Request:" not in daemon.output()
