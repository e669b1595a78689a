"""A TCP autopilot link that drops and comes back (the autopilot restarted): issue 13's
"RTCM data not injected: [Errno 106] Transport endpoint is already connected"."""

from __future__ import annotations

import asyncio
import logging
import time

import pytest

from aerobase.ports import free_port
from asset_agent.autopilot import Autopilot
from sim.vehicle.copter import CopterConfig
from sim.vehicle.habits import profile
from sim.vehicle.server import run_vehicle
from sim.vehicle.standalone import OpenPad
from tests.asset_agent.conftest import fast_config
from tests.polling import eventually

pytestmark = pytest.mark.slow  # an autopilot restart takes seconds

RTCM = bytes(range(60))  # any bytes: the test counts GPS_RTCM_DATA, not frames


async def test_rtcm_keeps_flowing_across_an_autopilot_restart_without_errno_106(caplog):
    caplog.set_level(logging.INFO, logger="asset_agent")
    port = free_port()
    pad = OpenPad()
    lag = 0.0
    async with run_vehicle(speed=5, seed=3, base=pad, tcp_port=port) as first:
        ap = Autopilot(fast_config(f"tcp:127.0.0.1:{port}", link_timeout_s=3.0))
        await ap.start()
        try:
            await ap.wait_link(10)
            stop = asyncio.Event()

            async def inject() -> None:  # corrections at 50 Hz, as the base streams them
                nonlocal lag
                while not stop.is_set():
                    t0 = time.monotonic()
                    ap.inject_rtcm(RTCM)
                    await asyncio.sleep(0.02)
                    lag = max(lag, time.monotonic() - t0 - 0.02)

            task = asyncio.create_task(inject())
            await eventually(lambda: first.copter._rtcm_inputs, 10, "RTCM at the autopilot")
        except BaseException:
            await ap.close()
            raise
    try:
        await asyncio.sleep(0.7)  # the autopilot is down this long (not a synchronisation)
        async with run_vehicle(speed=5, seed=3, base=pad, tcp_port=port) as back:
            await eventually(
                lambda: back.copter._rtcm_inputs, 15, "RTCM at the restarted autopilot"
            )
            await eventually(lambda: ap.link_up, 10, "link up again")
        stop.set()
        await task
    finally:
        await ap.close()
    texts = [r.getMessage() for r in caplog.records]
    assert not [t for t in texts if "Errno 106" in t or "already connected" in t], texts
    assert lag < 0.5, f"the event loop stalled {lag:.2f} s while the link reconnected"


async def test_streams_are_asked_for_again_on_a_new_tcp_connection():
    """The autopilot did not restart, but the TCP connection is new: a fresh channel that streams
    nothing until asked (a companion port's SRn_ rates are 0)."""
    config = CopterConfig(seed=3, habits=profile("ardupilot-4", boot_s=0.0))
    async with run_vehicle(speed=5, base=OpenPad(), config=config) as vehicle:
        ap = Autopilot(fast_config(f"tcp:127.0.0.1:{vehicle.tcp_port}", link_timeout_s=5.0))
        await ap.start()
        try:
            await ap.wait_link(10)
            await eventually(lambda: ap.state.lat is not None, 5, "position")
            negotiations = ap.streams.negotiations
            for writer in list(vehicle._writers):  # the connection drops; the autopilot runs on
                writer.close()
            await eventually(lambda: ap.streams.negotiations > negotiations, 10, "renegotiated")
            with ap.tap(lambda m: m.get_type() == "GLOBAL_POSITION_INT") as q:
                await asyncio.wait_for(q.get(), 3)
            assert ap.reboots == 0 and vehicle.copter.boots == 0
        finally:
            await ap.close()
