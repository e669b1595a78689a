"""The simulated autopilot's plan ids and its `stale_mission` fault (sim/vehicle/stale.py,
mission_report.py), seen by a raw MAVLink peer."""

from __future__ import annotations

import threading
from collections.abc import AsyncIterator
from typing import Any

import httpx
import pytest
from fastapi import FastAPI
from pymavlink import mavutil

from asset_agent.autopilot.translate import MISSION_ID_OFFSET, OPAQUE_ID_OFFSET, extension_u32
from sim.vehicle.control import vehicle_router
from sim.vehicle.copter import CopterConfig
from sim.vehicle.habits import profile
from sim.vehicle.server import VehicleServer, run_vehicle
from tests.polling import eventually

KINDS = [
    "MISSION_REQUEST_INT",
    "MISSION_ACK",
    "MISSION_CURRENT",
    "MISSION_ITEM_REACHED",
    "COMMAND_ACK",
]
COMPLETE, ACTIVE = 5, 3


class Recorder:
    """A raw peer recording the mission messages it hears, in order, on a thread."""

    def __init__(self, port: int) -> None:
        self.conn = mavutil.mavlink_connection(
            f"udpout:127.0.0.1:{port}", source_system=255, dialect="ardupilotmega"
        )
        self.heard: list[Any] = []
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._read, daemon=True)

    def _read(self) -> None:
        while not self._stop.is_set():
            msg = self.conn.recv_match(type=KINDS, blocking=True, timeout=0.1)
            if msg is not None:
                self.heard.append(msg)

    def listen(self) -> Recorder:
        self.conn.mav.heartbeat_send(6, 8, 0, 0, 0)  # the vehicle answers whoever spoke last
        self._thread.start()
        return self

    def stop(self) -> None:
        self._stop.set()
        self._thread.join(2)
        self.conn.close()

    def mark(self) -> int:
        return len(self.heard)

    async def wait(self, since: int, kind: str, within: float = 10.0, **match: Any) -> int:
        """The position of the first `kind` message after `since` whose fields match."""

        def found() -> int | None:
            for i in range(since, len(self.heard)):
                m = self.heard[i]
                if m.get_type() == kind and all(getattr(m, k) == v for k, v in match.items()):
                    return i
            return None

        await eventually(lambda: found() is not None, within, f"{kind} {match}")
        at = found()
        assert at is not None
        return at

    async def upload(self, items: list[tuple[int, float]]) -> int:
        """Upload home and `items` (command, altitude) at the pad; the final MISSION_ACK's index."""
        full = [(16, 0.0), *items]
        since = self.mark()
        self.conn.mav.mission_count_send(1, 1, len(full), 0)
        for seq in range(len(full)):
            await self.wait(since, "MISSION_REQUEST_INT", seq=seq)
            command, alt = full[seq]
            self.conn.mav.mission_item_int_send(
                1, 1, seq, 3, command, 0, 1, 0, 0, 0, 0, 0, 0, alt, 0
            )
        return await self.wait(since, "MISSION_ACK")

    async def command(self, command: int, *params: float) -> int:
        since = self.mark()
        p = [*params, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0][:7]
        self.conn.mav.command_long_send(1, 1, command, 0, *p)
        return await self.wait(since, "COMMAND_ACK", command=command)

    async def start(self) -> None:
        """GUIDED, arm, MISSION_START."""
        await self.command(176, 1, 4)  # GUIDED
        await self.command(400, 1)
        await self.command(300, 0, 0)


MISSION = [(22, 3.0), (21, 0.0)]  # take off to 3 m, land at home


@pytest.fixture
async def sim() -> AsyncIterator[VehicleServer]:
    async with run_vehicle(speed=10.0, config=CopterConfig(seed=5)) as server:
        yield server


async def _fault(sim: VehicleServer, **body: Any) -> dict[str, Any]:
    app = FastAPI()
    app.include_router(vehicle_router(sim))
    transport = httpx.ASGITransport(app=app)
    async with httpx.AsyncClient(transport=transport, base_url="http://sim") as http:
        r = await http.post("/vehicle/faults/stale_mission", json=body)
        assert r.status_code == 200, r.text
        bad = await http.post("/vehicle/faults/stale_mission", json={"repeat": 0})
        assert bad.status_code == 422
        return dict(r.json()["stale_mission"])


async def test_the_last_missions_end_comes_again_before_the_ack_at_arming_and_at_the_start(sim):
    peer = Recorder(sim.udp_port).listen()
    try:
        first_ack = await peer.upload(MISSION)
        plan_id = extension_u32(peer.heard[first_ack], "opaque_id", OPAQUE_ID_OFFSET)
        assert plan_id != 0  # ArduPilot 4.5+: the plan's CRC32 in the upload's ack
        await peer.start()
        await eventually(lambda: sim.copter.guidance.mission_state == COMPLETE, 30, "flown")
        await eventually(lambda: not sim.copter.armed, 30, "landed and disarmed")
        status = await _fault(sim, repeat=2)
        assert status["enabled"] and status["repeat"] == 2 and status["replayed"] == 0

        since = peer.mark()
        ack = await peer.upload(MISSION)  # the same plan again: the same id
        before_ack = peer.heard[since:ack]
        stale_current = [m for m in before_ack if m.get_type() == "MISSION_CURRENT"]
        stale_reached = [m for m in before_ack if m.get_type() == "MISSION_ITEM_REACHED"]
        assert len(stale_reached) == 2 and {m.seq for m in stale_reached} == {2}
        assert sum(1 for m in stale_current if m.mission_state == COMPLETE and m.seq == 2) >= 2
        assert extension_u32(peer.heard[ack], "opaque_id", OPAQUE_ID_OFFSET) == plan_id
        assert {extension_u32(m, "mission_id", MISSION_ID_OFFSET) for m in stale_current} == {
            plan_id
        }

        await peer.command(176, 1, 4)
        at_arming = peer.mark()
        arm_ack = await peer.command(400, 1)
        start_ack = await peer.command(300, 0, 0)
        between = [m.get_type() for m in peer.heard[at_arming:arm_ack]]
        assert between.count("MISSION_ITEM_REACHED") == 2, between  # late: after the arming
        started = [m.get_type() for m in peer.heard[arm_ack:start_ack]]
        assert started.count("MISSION_ITEM_REACHED") == 2, started  # late: in AUTO already
        # ...and the new mission's own report follows: running
        await peer.wait(start_ack, "MISSION_CURRENT", mission_state=ACTIVE)
        assert sim.copter.faults.stale_mission.status()["replayed"] == 3 * 2 * 2
    finally:
        peer.stop()


async def test_a_different_plan_has_another_id_and_an_old_release_sends_none():
    async with run_vehicle(speed=10.0, config=CopterConfig(seed=5)) as server:
        peer = Recorder(server.udp_port).listen()
        try:
            a = extension_u32(peer.heard[await peer.upload(MISSION)], "opaque_id", 4)
            b = extension_u32(peer.heard[await peer.upload([(22, 4.0), (21, 0.0)])], "opaque_id", 4)
            assert a and b and a != b
            since = peer.mark()
            at = await peer.wait(since, "MISSION_CURRENT")
            assert extension_u32(peer.heard[at], "mission_id", MISSION_ID_OFFSET) == b
        finally:
            peer.stop()
    old = CopterConfig(seed=5, habits=profile("ardupilot-3.7", boot_s=0, streams_at_boot="all"))
    async with run_vehicle(speed=10.0, config=old) as server:
        peer = Recorder(server.udp_port).listen()
        try:
            ack = peer.heard[await peer.upload(MISSION)]
            assert extension_u32(ack, "opaque_id", OPAQUE_ID_OFFSET) == 0
            at = await peer.wait(0, "MISSION_CURRENT")
            assert extension_u32(peer.heard[at], "mission_id", MISSION_ID_OFFSET) == 0
        finally:
            peer.stop()
