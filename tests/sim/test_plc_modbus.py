"""The simulated PLC over real Modbus TCP with a raw pymodbus client (the daemon bypassed)."""

from __future__ import annotations

import asyncio
import time
from collections.abc import AsyncIterator

import httpx
import pytest
from pymodbus.client import AsyncModbusTcpClient
from pymodbus.exceptions import ModbusException

from sim.plc import LandingBase, PlcServer
from sim.weather import Weather, WeatherParams
from sim.world import World, parse_args
from tests.polling import eventually

UNIT = 1


@pytest.fixture
async def plc(world: World) -> AsyncIterator[AsyncModbusTcpClient]:
    """A raw Modbus TCP client connected to the world's PLC."""
    client = AsyncModbusTcpClient("127.0.0.1", port=world.ports["plc"], timeout=1, retries=0)
    assert await client.connect()
    yield client
    client.close()


async def di(c: AsyncModbusTcpClient) -> list[bool]:
    return (await c.read_discrete_inputs(0, count=11, device_id=UNIT)).bits[:11]


async def ir(c: AsyncModbusTcpClient) -> list[int]:
    return (await c.read_input_registers(0, count=20, device_id=UNIT)).registers


async def coil(c: AsyncModbusTcpClient, address: int) -> None:
    assert not (await c.write_coil(address, True, device_id=UNIT)).isError()


async def test_power_up_image(world: World, plc: AsyncModbusTcpClient) -> None:
    bits = await di(plc)
    assert bits[1] and bits[3] and not bits[0] and not bits[2]  # closed and down
    assert bits[8]  # grid present
    regs = await ir(plc)
    assert regs[16] == 0 and regs[17] == 0 and regs[18] == 0
    assert regs[11] == 65535  # no UAV battery known
    assert (await plc.read_coils(0, count=7, device_id=UNIT)).bits[:7] == [False] * 7
    hr = (await plc.read_holding_registers(0, count=2, device_id=UNIT)).registers
    assert hr[1] == 5000


async def test_plc_refuses_lift_up_with_panels_closed_and_clears_the_coil(
    world: World, plc: AsyncModbusTcpClient
) -> None:
    await coil(plc, 2)
    assert (await di(plc))[10]  # INTERLOCK_REFUSED
    assert (await plc.read_coils(0, count=7, device_id=UNIT)).bits[2] is False
    assert not world.base.lift.moving
    await coil(plc, 0)  # PANELS_OPEN accepted: clears INTERLOCK_REFUSED
    assert not (await di(plc))[10] and (await di(plc))[4]


@pytest.mark.slow
async def test_full_cycle_and_panels_close_refused_with_lift_up(
    world: World, plc: AsyncModbusTcpClient
) -> None:
    await coil(plc, 0)
    await eventually(lambda: world.base.panels.at_high, 5, "panels open")
    await coil(plc, 2)
    await eventually(lambda: world.base.lift.at_high, 5, "lift up")
    bits = await di(plc)
    assert bits[0] and bits[2] and not bits[4] and not bits[5]
    assert (await ir(plc))[16:18] == [1000, 1000]
    await coil(plc, 1)  # PANELS_CLOSE with the lift up
    assert (await di(plc))[10] and world.base.panels.at_high
    await coil(plc, 3)
    await eventually(lambda: world.base.lift.at_low, 5, "lift down")
    await coil(plc, 1)
    await eventually(lambda: world.base.panels.at_low, 5, "panels closed")


async def test_no_motion_under_estop_or_latched_fault_and_reset_rules(
    world: World, plc: AsyncModbusTcpClient
) -> None:
    async with httpx.AsyncClient(base_url=f"http://127.0.0.1:{world.ports['control']}") as h:
        await h.post("/faults/estop", json={"on": True})
        bits = await di(plc)
        assert bits[6] and (await ir(plc))[18] & 32
        await coil(plc, 0)
        assert (await di(plc))[10] and not world.base.panels.moving
        await coil(plc, 6)  # FAULT_RESET does not clear an active E-stop
        assert (await ir(plc))[18] & 32
        await h.post("/faults/estop", json={"on": False})
        await coil(plc, 0)
        assert (await di(plc))[10]  # still latched
        await coil(plc, 6)
        assert (await ir(plc))[18] == 0
        r = await h.post("/faults/stall", json={"axis": "lift", "on": True, "immediate": True})
        assert r.json()["state"]["faults"] & 2
        await coil(plc, 0)
        assert (await di(plc))[10] and not world.base.panels.moving


async def test_stall_detected_after_travel_plus_50_percent(
    world: World, plc: AsyncModbusTcpClient
) -> None:
    world.base.inject_stall("panels")
    await coil(plc, 0)
    assert (await di(plc))[4]
    await eventually(lambda: world.base.fault_bits() & 1, 5, "panel stall latched")
    assert not (await di(plc))[4] and (await ir(plc))[18] & 1
    assert world.base.t_sim >= 18.0


async def test_heartbeat_counts_in_wall_time(world: World, plc: AsyncModbusTcpClient) -> None:
    first = (await ir(plc))[19]
    await eventually(lambda: world.base.heartbeat >= first + 3, 2, "three heartbeats")
    assert (await ir(plc))[19] >= first + 3


async def test_the_heartbeat_is_current_at_every_read_with_nothing_stepping_the_model() -> None:
    """A real PLC counts its heartbeat on its own CPU: a stall of the process serving ours (the
    world's step loop) must not freeze it, or the daemon reads a live PLC as halted."""
    base = LandingBase(Weather(7, WeatherParams()), seed=7)
    base.tick_wall(time.monotonic())
    server = PlcServer(base)  # no world, so no step loop: only the reads can advance it
    await server.start()
    client = AsyncModbusTcpClient("127.0.0.1", port=server.port, timeout=1, retries=0)
    try:
        assert await client.connect()
        first = (await ir(client))[19]

        async def counted_on() -> bool:
            return (await ir(client))[19] >= first + 3  # three of its 100 ms ticks

        await eventually(counted_on, 2, "the heartbeat read over Modbus to count on")
    finally:
        client.close()
        await server.stop()


@pytest.mark.slow
async def test_watchdog_armed_by_first_write_expires_after_2_s(
    world: World, plc: AsyncModbusTcpClient
) -> None:
    assert not world.base.watchdog_armed
    await plc.write_register(0, 1, device_id=UNIT)
    world.base.panels.travel_s = 1000.0  # keep moving long enough to see the watchdog act
    await coil(plc, 0)
    await eventually(lambda: world.base.fault_bits() & 16, 4, "watchdog fault")
    assert not (await di(plc))[4] and (await ir(plc))[18] & 16


@pytest.mark.slow
async def test_watchdog_fed_by_a_changing_value_never_expires(
    world: World, plc: AsyncModbusTcpClient
) -> None:
    for i in range(12):  # 3 s of feeding every 250 ms
        await plc.write_register(0, i + 1, device_id=UNIT)
        await asyncio.sleep(0.25)  # pacing the master, as a real one does
    assert world.base.fault_bits() == 0


async def test_mass_32_bit_high_word_first(world: World, plc: AsyncModbusTcpClient) -> None:
    world.base.set_pad_load(70_000.0, True)
    await eventually(lambda: world.base.scale_g > 70_000, 2, "scale updated")
    regs = await ir(plc)
    assert regs[0] == 1 and abs(((regs[0] << 16) | regs[1]) - 70_015) < 15


async def test_link_cut_and_freeze(world: World, plc: AsyncModbusTcpClient) -> None:
    async with httpx.AsyncClient(base_url=f"http://127.0.0.1:{world.ports['control']}") as h:
        await h.post("/faults/link", json={"mode": "freeze"})
        frozen = AsyncModbusTcpClient("127.0.0.1", port=world.ports["plc"], timeout=0.3, retries=0)
        assert await frozen.connect()  # accepted ...
        with pytest.raises(ModbusException):  # ... but never answered
            await frozen.read_input_registers(0, count=20, device_id=UNIT)
        frozen.close()
        await h.post("/faults/link", json={"mode": "cut"})
        cut = AsyncModbusTcpClient("127.0.0.1", port=world.ports["plc"], timeout=0.3, retries=0)
        await cut.connect()
        with pytest.raises(ModbusException):
            await cut.read_input_registers(0, count=20, device_id=UNIT)
        cut.close()
        await h.post("/faults/link", json={"mode": "normal"})
        ok = AsyncModbusTcpClient("127.0.0.1", port=world.ports["plc"], timeout=1, retries=0)
        assert await ok.connect()
        assert len(await ir(ok)) == 20
        ok.close()


async def test_control_api_reports_errors_as_json(world: World) -> None:
    async with httpx.AsyncClient(base_url=f"http://127.0.0.1:{world.ports['control']}") as h:
        r = await h.post("/faults/stall", json={"axis": "door"})
        assert r.status_code == 400 and r.json()["error"]["code"] == "invalid"
        r = await h.post("/weather/scenario", json={"name": "tornado"})
        assert r.status_code == 404 and "storm" in r.json()["error"]["message"]
        r = await h.post("/weather/scenario", json={"name": "storm"})
        assert r.json()["state"]["weather"]["wind_mps"] == 6.0
        health = (await h.get("/health")).json()
        assert health["ports"]["plc"] == world.ports["plc"]
        state = (await h.get("/state")).json()
        assert state["link"] == "normal" and state["can_vehicle_leave"] is False


def test_command_line_flags() -> None:
    cfg = parse_args(
        [
            "--speed",
            "5",
            "--seed",
            "3",
            "--plc-port",
            "1502",
            "--gnss-port",
            "1503",
            "--mavlink-port",
            "1504",
            "--control-port",
            "1505",
            "--host",
            "0.0.0.0",
        ]
    )
    assert (cfg.speed, cfg.seed, cfg.plc_port, cfg.control_port, cfg.host) == (
        5.0,
        3,
        1502,
        1505,
        "0.0.0.0",
    )


def test_vehicle_facing_api(world: World) -> None:
    base = world.base
    assert base.pad_geodetic == (41.1780, -8.5980, 120.0)
    assert not base.can_vehicle_leave()
    base.panels.position = base.lift.position = 1.0
    assert base.can_vehicle_leave()
    n, e = world.weather.wind_ne(world.base.t_sim)
    assert isinstance(n, float) and isinstance(e, float)


async def test_bad_requests_get_exception_responses_and_the_plc_keeps_serving(
    world: World, plc: AsyncModbusTcpClient
) -> None:
    assert (await plc.read_input_registers(0, count=30, device_id=UNIT)).isError()
    assert (await plc.write_register(5, 1, device_id=UNIT)).isError()
    assert (await plc.write_coil(40, True, device_id=UNIT)).isError()
    assert (await plc.read_input_registers(0, count=5, device_id=2)).isError()  # not unit 1
    assert len(await ir(plc)) == 20 and plc.connected
    assert world.base.command_log == []
