"""The simulated autopilot seen by a raw MAVLink peer (pymavlink over UDP/TCP), its control routes and its place in the world."""

from __future__ import annotations

import asyncio
import math
import random
import socket
import time
from collections.abc import AsyncIterator
from typing import Any

import httpx
import pytest
from fastapi import FastAPI
from pymavlink import mavutil

from sim.vehicle.control import vehicle_router
from sim.vehicle.copter import CopterConfig
from sim.vehicle.part import VehiclePart
from sim.vehicle.server import VehicleServer, run_vehicle
from sim.world import World, WorldConfig
from tests.polling import eventually


class Peer:
    """A raw pymavlink peer; blocking reads run in a thread."""

    def __init__(self, url: str) -> None:
        self.conn = mavutil.mavlink_connection(url, source_system=255, dialect="ardupilotmega")

    async def recv(self, kind: str, within: float = 5.0, **match: Any) -> Any:
        """The next `kind` message whose fields equal `match`, or fail after `within` s."""
        deadline = time.monotonic() + within

        def read() -> Any:
            while time.monotonic() < deadline:
                msg = self.conn.recv_match(type=kind, blocking=True, timeout=0.2)
                if msg is not None and all(getattr(msg, k) == v for k, v in match.items()):
                    return msg
            return None

        msg = await asyncio.to_thread(read)
        assert msg is not None, f"no {kind} {match} within {within} s"
        return msg

    async def ack_and_text(self, command: int) -> tuple[Any, str]:
        """The COMMAND_ACK for `command` and the STATUSTEXT sent just before it."""
        text = ""

        def read() -> Any:
            nonlocal text
            deadline = time.monotonic() + 5
            while time.monotonic() < deadline:
                msg = self.conn.recv_match(
                    type=["COMMAND_ACK", "STATUSTEXT"], blocking=True, timeout=0.2
                )
                if msg is None:
                    continue
                if msg.get_type() == "STATUSTEXT":
                    text = msg.text
                elif msg.command == command:
                    return msg
            return None

        ack = await asyncio.to_thread(read)
        assert ack is not None, f"no COMMAND_ACK for {command}"
        return ack, text

    async def count(self, kinds: tuple[str, ...], until: str, n: int) -> dict[str, int]:
        """Count messages of `kinds` until `n` messages of type `until` have arrived."""
        counts = dict.fromkeys((*kinds, until), 0)

        def read() -> None:
            deadline = time.monotonic() + 15
            while counts[until] < n and time.monotonic() < deadline:
                msg = self.conn.recv_match(type=[*kinds, until], blocking=True, timeout=0.2)
                if msg is not None:
                    counts[msg.get_type()] += 1

        await asyncio.to_thread(read)
        assert counts[until] >= n
        return counts

    def close(self) -> None:
        """Close the connection."""
        self.conn.close()


@pytest.fixture
async def sim() -> AsyncIterator[VehicleServer]:
    """A vehicle at 10x on free ports (mission upload cancelled after 3 s of silence, not 8)."""
    config = CopterConfig(seed=3, mission_timeout_s=3.0)
    async with run_vehicle(speed=10.0, config=config) as server:
        yield server


@pytest.fixture
async def peer(sim: VehicleServer) -> AsyncIterator[Peer]:
    """A raw peer on the vehicle's UDP port that has announced itself."""
    p = Peer(f"udpout:127.0.0.1:{sim.udp_port}")
    p.conn.mav.heartbeat_send(6, 8, 0, 0, 0)
    await p.recv("HEARTBEAT")
    yield p
    p.close()


@pytest.mark.slow
async def test_identity_and_mode_numbers(peer: Peer) -> None:
    hb = await peer.recv("HEARTBEAT")
    assert (hb.type, hb.autopilot, hb.custom_mode) == (
        2,
        3,
        0,
    )  # QUADROTOR, ARDUPILOTMEGA, STABILIZE
    assert hb.get_srcSystem() == 1 and hb.get_srcComponent() == 1
    peer.conn.mav.set_mode_send(1, 1, 5)  # SET_MODE LOITER
    assert (await peer.recv("COMMAND_ACK", command=11)).result == 0
    await peer.recv("HEARTBEAT", custom_mode=5)
    peer.conn.mav.command_long_send(1, 1, 176, 0, 1, 99, 0, 0, 0, 0, 0)  # unknown mode number
    assert (await peer.recv("COMMAND_ACK", command=176)).result == 4  # FAILED
    peer.conn.mav.command_int_send(1, 1, 0, 42, 0, 0, 0, 0, 0, 0, 0, 0, 0)  # unknown command
    assert (await peer.recv("COMMAND_ACK", command=42)).result == 3  # UNSUPPORTED


@pytest.mark.slow
async def test_request_data_stream_and_request_message(peer: Peer) -> None:
    peer.conn.mav.request_data_stream_send(1, 1, 6, 0, 0)  # stop POSITION
    await peer.recv("HEARTBEAT")  # let in-flight messages pass
    counts = await peer.count(("GLOBAL_POSITION_INT",), "HEARTBEAT", 2)
    assert counts["GLOBAL_POSITION_INT"] <= 1
    peer.conn.mav.request_data_stream_send(1, 1, 6, 20, 1)  # POSITION at 20 Hz
    await peer.recv("GLOBAL_POSITION_INT")
    peer.conn.mav.command_long_send(1, 1, 512, 0, 242, 0, 0, 0, 0, 0, 0)  # REQUEST_MESSAGE HOME
    assert (await peer.recv("COMMAND_ACK", command=512)).result == 0
    home = await peer.recv("HOME_POSITION")
    assert (home.latitude, home.longitude) == (411780000, -85960000)


@pytest.mark.slow  # one interval of 3 s
async def test_a_message_given_an_interval_comes_first_one_interval_later(peer: Peer) -> None:
    """As ArduPilot's `set_ap_message_interval`: a new bucket, last sent now."""
    peer.conn.mav.command_long_send(1, 1, 511, 0, 242, 3e6, 0, 0, 0, 0, 0)  # HOME every 3 s
    assert (await peer.recv("COMMAND_ACK", command=511)).result == 0
    t0 = time.monotonic()
    await peer.recv("HOME_POSITION", within=8)
    assert time.monotonic() - t0 > 2.5  # not at once: one interval on (a late one only later)


async def test_mission_download_starts_with_home_and_clear_all(peer: Peer) -> None:
    peer.conn.mav.mission_request_list_send(1, 1, 0)
    assert (await peer.recv("MISSION_COUNT")).count == 1
    peer.conn.mav.mission_request_int_send(1, 1, 0, 0)
    home = await peer.recv("MISSION_ITEM_INT", seq=0)
    assert (home.x, home.y, home.command) == (411780000, -85960000, 16)
    peer.conn.mav.mission_request_int_send(1, 1, 5, 0)
    assert (await peer.recv("MISSION_ACK")).type == 13  # INVALID_SEQUENCE
    peer.conn.mav.mission_clear_all_send(1, 1, 0)
    assert (await peer.recv("MISSION_ACK")).type == 0


@pytest.mark.slow
async def test_autopilot_re_requests_then_cancels_an_abandoned_upload(peer: Peer) -> None:
    peer.conn.mav.mission_count_send(1, 1, 3, 0)
    assert (await peer.recv("MISSION_REQUEST_INT")).seq == 0
    again = await peer.recv("MISSION_REQUEST_INT", within=3)  # re-requested after 1 s of silence
    assert again.seq == 0
    ack = await peer.recv("MISSION_ACK", within=8)
    assert ack.type == 15  # MAV_MISSION_OPERATION_CANCELLED after the upload timeout


@pytest.mark.slow
async def test_tcp_clients_get_streams_and_replies(sim: VehicleServer, peer: Peer) -> None:
    p = Peer(f"tcp:127.0.0.1:{sim.tcp_port}")
    try:
        await p.recv("HEARTBEAT")
        # rates are per link: the TCP client stops ATTITUDE, the UDP peer keeps it
        p.conn.mav.command_long_send(1, 1, 511, 0, 30, -1, 0, 0, 0, 0, 0)
        assert (await p.recv("COMMAND_ACK", command=511)).result == 0
        await p.recv("HEARTBEAT")
        assert (await p.count(("ATTITUDE",), "HEARTBEAT", 2))["ATTITUDE"] == 0
        await peer.recv("ATTITUDE")
        p.conn.mav.command_long_send(1, 1, 400, 0, 1, 0, 0, 0, 0, 0, 0)
        assert (await p.recv("COMMAND_ACK", command=400)).result == 0
        await p.recv("HEARTBEAT", base_mode=1 | 16 | 128)
    finally:
        p.close()


async def test_control_routes_truth_and_faults(sim: VehicleServer, peer: Peer) -> None:
    app = FastAPI()
    app.include_router(vehicle_router(sim))
    async with httpx.AsyncClient(
        transport=httpx.ASGITransport(app=app), base_url="http://sim"
    ) as http:
        truth = (await http.get("/vehicle/truth")).json()
        assert truth["landed"] is True and truth["distance_to_pad_m"] == 0.0
        assert truth["gnss"]["fix_type"] == 3
        r = await http.post("/vehicle/faults/prearm", json={"reason": "Injected failure"})
        assert r.json()["prearm_failure"] == "Injected failure"
        peer.conn.mav.command_long_send(1, 1, 400, 0, 1, 0, 0, 0, 0, 0, 0)
        ack, text = await peer.ack_and_text(400)
        assert (ack.result, text) == (4, "PreArm: Injected failure")
        lost = (await http.post("/vehicle/faults/drop_acks", json={"count": 1})).json()
        assert lost["drop_acks"] == 1
        for confirmation in (0, 1):  # the first answer lost, the second heard
            peer.conn.mav.command_long_send(1, 1, 400, confirmation, 1, 0, 0, 0, 0, 0, 0)
        assert (await peer.ack_and_text(400))[0].result == 4
        assert (await http.get("/vehicle/faults")).json()["drop_acks"] == 0
        assert (await http.post("/vehicle/battery", json={"percent": 42})).json()[
            "battery_pct"
        ] == 42
        assert (await peer.recv("SYS_STATUS", battery_remaining=42)).battery_remaining == 42
        await http.post("/vehicle/faults/gnss_bias", json={"north_m": 2.0, "east_m": 0.0})
        assert (await http.get("/vehicle/faults")).json()["gnss_bias_ne_m"] == [2.0, 0.0]
        assert (await http.post("/vehicle/faults/mute", json={"seconds": 30})).json()["muted"]
        assert sim.muted()
        assert (await http.post("/vehicle/battery", json={"percent": 142})).status_code == 422
        cleared = (await http.post("/vehicle/faults/clear")).json()
        stale = cleared.pop("stale_mission")
        assert cleared == {
            "prearm_failure": None, "muted": False, "mute_remaining_s": 0.0,
            "drop_mission": False, "drop_acks": 0, "no_gnss_fix": False,
            "gnss_bias_ne_m": [0.0, 0.0],
        }  # fmt: skip
        assert stale["enabled"] is False
        await peer.recv("HEARTBEAT")


async def test_vehicle_in_the_world_sits_on_the_closed_base() -> None:
    world = World(WorldConfig.for_tests(speed=20.0, seed=5))
    world.add_part(VehiclePart())
    async with world:
        assert world.base.pad_mass_g > 0 and world.base.contacts_seated
        assert world.base.charger.uav_soc == 1.0  # the vehicle's battery sits on the contacts
        world.base.set_uav_battery(0.5)  # as if the base's charger had a half-full pack
        await eventually(
            lambda: abs(world.parts[0].server.copter.dyn.state.battery_pct - 50) < 0.1, 5
        )
        peer = Peer(f"udpout:127.0.0.1:{world.ports['mavlink_udp']}")
        try:
            peer.conn.mav.heartbeat_send(6, 8, 0, 0, 0)
            await peer.recv("HEARTBEAT")
            peer.conn.mav.command_long_send(1, 1, 400, 0, 1, 0, 0, 0, 0, 0, 0)
            ack, text = await peer.ack_and_text(400)
            assert (ack.result, text) == (4, "PreArm: Base closed")
        finally:
            peer.close()
        async with httpx.AsyncClient(base_url=f"http://127.0.0.1:{world.ports['control']}") as http:
            truth = (await http.get("/vehicle/truth")).json()
        assert truth["landed"] and truth["ports"]["mavlink_tcp"] == world.ports["mavlink_tcp"]


async def test_garbage_never_stops_the_vehicle(sim: VehicleServer, peer: Peer) -> None:
    rng = random.Random(1)
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as udp:
        for _ in range(50):
            udp.sendto(
                bytes(rng.randrange(256) for _ in range(rng.randrange(1, 300))),
                ("127.0.0.1", sim.udp_port),
            )
        udp.sendto(
            b"\xfd\x09\x00\x00\x00\xff\xbe\x00\x00\x00" + bytes(20), ("127.0.0.1", sim.udp_port)
        )
    _reader, writer = await asyncio.open_connection("127.0.0.1", sim.tcp_port)
    writer.write(bytes(rng.randrange(256) for _ in range(5000)))
    await writer.drain()
    writer.close()
    # a message addressed to another system is ignored, not answered
    peer.conn.mav.command_long_send(7, 1, 400, 0, 1, 0, 0, 0, 0, 0, 0)
    peer.conn.mav.command_long_send(1, 1, 400, 0, 0, 0, 0, 0, 0, 0, 0)
    ack = await peer.recv("COMMAND_ACK", command=400)
    assert ack.result == 0 and not sim.copter.armed


async def test_guided_global_target_and_condition_yaw(sim: VehicleServer, peer: Peer) -> None:
    c = sim.copter
    peer.conn.mav.set_mode_send(1, 1, 4)
    await peer.recv("COMMAND_ACK", command=11)
    peer.conn.mav.command_long_send(1, 1, 400, 0, 1, 0, 0, 0, 0, 0, 0)
    assert (await peer.recv("COMMAND_ACK", command=400)).result == 0
    peer.conn.mav.command_long_send(1, 1, 22, 0, 0, 0, 0, 0, 0, 0, 5)
    assert (await peer.recv("COMMAND_ACK", command=22)).result == 0
    await eventually(lambda: c.dyn.state.altitude > 4.5, 10, "takeoff")
    peer.conn.mav.command_long_send(1, 1, 115, 0, 90, 0, 1, 0, 0, 0, 0)  # CONDITION_YAW east
    assert (await peer.recv("COMMAND_ACK", command=115)).result == 0
    await eventually(lambda: abs(c.dyn.state.yaw - math.pi / 2) < 0.02, 10, "facing east")
    lat, lon, _ = c.origin.to_geodetic(-10.0, 5.0, 0.0)
    mask = 0b0000_1101_1111_1000  # position only, keep the yaw
    peer.conn.mav.set_position_target_global_int_send(
        0, 1, 1, 6, mask, round(lat * 1e7), round(lon * 1e7), 8.0, 0, 0, 0, 0, 0, 0, 0, 0
    )
    # the autopilot flies its estimate: the estimated position reaches the target
    await eventually(
        lambda: (
            math.dist(c.estimated_position()[:2], (-10.0, 5.0)) < 0.5 and c.dyn.state.altitude > 7.5
        ),
        20,
        f"at the global target (now {c.estimated_position()})",
    )


async def test_guided_on_the_ground_lifts_off_for_a_takeoff_not_for_a_climb_target(
    sim: VehicleServer, peer: Peer
) -> None:
    """ArduPilot's GUIDED controllers idle while landed (`is_disarmed_or_landed`): a velocity
    target that climbs, sent to an armed vehicle on the ground, leaves it there; a takeoff
    command lifts it."""
    c = sim.copter
    peer.conn.mav.set_mode_send(1, 1, 4)  # GUIDED
    await peer.recv("COMMAND_ACK", command=11)
    peer.conn.mav.command_long_send(1, 1, 400, 0, 1, 0, 0, 0, 0, 0, 0)
    assert (await peer.recv("COMMAND_ACK", command=400)).result == 0
    start = c.t
    velocity_only = 0b0000_1101_1100_0111
    while c.t < start + 2.0:  # two simulated seconds of climb targets, one every 0.1 s
        peer.conn.mav.set_position_target_local_ned_send(
            0, 1, 1, 1, velocity_only, 0, 0, 0, 0.5, 0, -1.5, 0, 0, 0, 0, 0
        )
        sent = c.t
        await eventually(lambda sent=sent: c.t >= sent + 0.1, 5, "simulated time")
    assert c.dyn.state.landed and c.dyn.state.altitude < 0.05 and c.armed
    peer.conn.mav.command_long_send(1, 1, 22, 0, 0, 0, 0, 0, 0, 0, 3)
    assert (await peer.recv("COMMAND_ACK", command=22)).result == 0
    await eventually(lambda: c.dyn.state.altitude > 2.5, 10, "takeoff")
