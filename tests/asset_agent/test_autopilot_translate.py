"""Pure translation of MAVLink messages to UavState, and the mission item converter."""

from __future__ import annotations

import math

import pytest
from pymavlink.dialects.v20 import ardupilotmega as m

from asset_agent.autopilot import InvalidMissionItem, MissionItem, items_from_dicts, items_to_dicts
from asset_agent.autopilot.state import UavState
from asset_agent.autopilot.translate import apply


def test_heartbeat_gives_mode_armed_and_status() -> None:
    s = apply(UavState(), m.MAVLink_heartbeat_message(2, 3, 1 | 16 | 8 | 128, 6, 4, 3))
    assert (s.mode, s.custom_mode, s.armed, s.system_status) == ("RTL", 6, True, 4)
    s = apply(s, m.MAVLink_heartbeat_message(2, 3, 1 | 16, 17, 3, 3))
    assert (s.mode, s.armed) == ("BRAKE", False)


def test_position_velocity_and_heading() -> None:
    msg = m.MAVLink_global_position_int_message(
        0, 411780000, -85960000, 135500, 15500, 120, -50, 30, 9000
    )
    s = apply(UavState(), msg)
    assert (s.lat, s.lon, s.alt_msl, s.alt_rel) == (41.178, -8.596, 135.5, 15.5)
    assert (s.vn, s.ve, s.vd, s.heading_deg) == (1.2, -0.5, 0.3, 90.0)


def test_gnss_fix_types_including_rtk() -> None:
    for fix, name in ((3, "3D"), (5, "RTK_FLOAT"), (6, "RTK_FIXED"), (1, "NO_FIX")):
        msg = m.MAVLink_gps_raw_int_message(0, fix, 0, 0, 0, 70, 100, 0, 0, 21)
        s = apply(UavState(), msg)
        assert (s.fix_type, s.fix_name, s.satellites, s.hdop) == (fix, name, 21, 0.7)


def test_battery_attitude_landed_state_and_mission() -> None:
    s = apply(
        UavState(),
        m.MAVLink_battery_status_message(0, 0, 1, 0, [4000] * 4 + [65535] * 6, 1520, 300, -1, 77),
    )
    assert (s.voltage_v, s.current_a, s.battery_pct) == (16.0, 15.2, 77.0)
    s = apply(s, m.MAVLink_sys_status_message(7, 7, 5, 0, 15800, 1000, 76, 0, 0, 0, 0, 0, 0))
    assert s.sensors_healthy is False and s.battery_pct == 76 and s.voltage_v == 15.8
    rc = 0x10000  # an unhealthy RC receiver does not matter to a companion-driven vehicle
    s = apply(
        s, m.MAVLink_sys_status_message(7 | rc, 7 | rc, 7, 0, 15800, 1000, 76, 0, 0, 0, 0, 0, 0)
    )
    assert s.sensors_healthy is True
    s = apply(
        s,
        m.MAVLink_attitude_message(
            0, math.radians(10), math.radians(-5), math.radians(-90), 0, 0, 0
        ),
    )
    assert s.roll_deg == pytest.approx(10) and s.yaw_deg == pytest.approx(270)
    s = apply(s, m.MAVLink_extended_sys_state_message(0, 4))
    assert s.landed_state == "LANDING" and s.in_air
    s = apply(s, m.MAVLink_mission_current_message(3, 10, 3, 1))
    assert (s.mission_current, s.mission_total, s.mission_state) == (2, 10, "ACTIVE")
    assert apply(s, m.MAVLink_mission_current_message(0, 0xFFFF, 1, 0)).mission_total == 0
    s = apply(
        s,
        m.MAVLink_home_position_message(
            411780000, -85960000, 120000, 0, 0, 0, [1, 0, 0, 0], 0, 0, 0
        ),
    )
    assert (s.home_lat, s.home_lon, s.home_alt_msl) == (41.178, -8.596, 120.0)


def test_unknown_message_leaves_state_unchanged() -> None:
    s = UavState(mode="AUTO")
    assert apply(s, m.MAVLink_vfr_hud_message(1, 1, 0, 0, 0, 0)) is s


def test_mission_dicts_round_trip() -> None:
    d = [
        {"command": 22, "frame": 3, "params": [0, 0, 0, None], "lat": 0, "lon": 0, "alt": 10, "autocontinue": True},
        {"command": 16, "frame": 6, "params": [2.5, 1, 0, 0], "lat": 41.1780123, "lon": -8.5960456, "alt": 30.5, "autocontinue": True},
    ]  # fmt: skip
    items = items_from_dicts(d)
    assert items[1] == MissionItem(16, 6, 2.5, 1, 0, 0, 411780123, -85960456, 30.5, 1)
    assert math.isnan(items[0].param4)
    assert items_to_dicts(items) == [
        {**x, "params": [float(p) if p is not None else None for p in x["params"]]} for x in d
    ]


@pytest.mark.parametrize(
    ("patch", "field"),
    [
        ({"lat": 90.5}, "lat"),
        ({"lon": -181}, "lon"),
        ({"alt": 20000}, "alt"),
        ({"command": "WAYPOINT"}, "command"),
        ({"frame": 1}, "frame"),
        ({"params": [1, 2, 3]}, "params"),
        ({"params": [1, 2, 3, math.inf]}, "params"),
        ({"lat": "north"}, "lat"),
    ],
)
def test_bad_items_name_their_index_and_field(patch: dict, field: str) -> None:
    good = {"command": 16, "frame": 3, "params": [0, 0, 0, 0], "lat": 41.0, "lon": -8.0, "alt": 10}
    with pytest.raises(InvalidMissionItem) as info:
        items_from_dicts([good, good, {**good, **patch}])
    assert info.value.index == 2
    assert field in info.value.reason


def test_not_a_list() -> None:
    with pytest.raises(InvalidMissionItem) as info:
        items_from_dicts("16,3,...")  # type: ignore[arg-type]
    assert info.value.index is None


async def test_a_malformed_message_is_logged_not_raised() -> None:
    from asset_agent.autopilot import Autopilot

    ap = Autopilot()
    bad = m.MAVLink_global_position_int_message(0, 1, 2, 3, 4, 5, 6, 7, 8)
    bad.lat = "garbage"  # a field that cannot be scaled
    bad._header = m.MAVLink_header(33, srcSystem=1, srcComponent=1)
    ap._on_message(bad)  # must not raise
    assert ap.state.lat is None


async def test_command_acks_for_another_ground_station_are_not_ours() -> None:
    from asset_agent.autopilot import Autopilot

    ap = Autopilot()
    assert ap._ack_for_us(m.MAVLink_command_ack_message(400, 0), 400)  # not addressed: ours
    assert ap._ack_for_us(m.MAVLink_command_ack_message(400, 0, 0, 0, 1, 191), 400)
    assert not ap._ack_for_us(m.MAVLink_command_ack_message(400, 0, 0, 0, 255, 190), 400)  # a GCS
    assert not ap._ack_for_us(m.MAVLink_command_ack_message(176, 0), 400)
