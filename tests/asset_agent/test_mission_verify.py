"""Each rule of mission verification (asset_agent/autopilot/verify.py), and every MISSION_ACK result."""

from __future__ import annotations

import math

import pytest

from asset_agent.autopilot.errors import MAV_MISSION_RESULT_NAMES, mission_result_text
from asset_agent.autopilot.items import MissionItem, items_from_dicts
from asset_agent.autopilot.verify import compare
from sim.vehicle import mission as ms
from sim.vehicle.habits import stored

NAN = math.nan
WP = MissionItem(16, 3, 0.0, 0.0, 0.0, NAN, 473977420, 85455940, 20.0)


def _as_sim_stores(item: MissionItem) -> MissionItem:
    """What the simulated ArduPilot (AP_Mission's packing) gives back for `item`."""
    it = ms.Item(1, item.frame, item.command, item.param1, item.param2, item.param3,
                 item.param4, item.x, item.y, item.z, item.autocontinue)  # fmt: skip
    s = stored(it)
    return MissionItem(s.command, s.frame, s.param1, s.param2, s.param3, s.param4, s.x, s.y, s.z,
                       s.autocontinue)  # fmt: skip


def _with(item: MissionItem, **kw: float) -> MissionItem:
    from dataclasses import replace

    return replace(item, **kw)  # type: ignore[arg-type]


def test_the_command_must_match():
    assert compare(WP, _with(WP, command=17)).field == "command"  # type: ignore[union-attr]


def test_int_and_plain_frames_are_one_frame_but_relative_is_not_absolute():
    assert compare(_with(WP, frame=6), _with(WP, frame=3)) is None
    assert compare(_with(WP, frame=5), _with(WP, frame=0)) is None
    assert compare(WP, _with(WP, frame=0)).field == "frame"  # type: ignore[union-attr]


def test_commands_without_a_position_accept_any_frame_and_position():
    speed = MissionItem(178, 2, 1.0, 5.0, -1.0, 0.0)
    assert compare(speed, _with(speed, frame=0, x=5, y=7, z=3.0)) is None
    rtl = MissionItem(20, 3, 0, 0, 0, 0, 123, 456, 30.0)
    assert compare(rtl, MissionItem(20, 0)) is None  # ArduPilot keeps nothing of an RTL


def test_coordinates_match_to_one_unit_of_1e7_degrees():
    assert compare(WP, _with(WP, x=WP.x - 1, y=WP.y + 1)) is None  # PX4's truncation
    assert compare(WP, _with(WP, x=WP.x + 2)).field == "x"  # type: ignore[union-attr]
    assert compare(WP, _with(WP, y=WP.y - 2)).field == "y"  # type: ignore[union-attr]


def test_altitude_matches_to_the_centimetre_ardupilot_keeps():
    assert compare(_with(WP, z=15.129), _with(WP, z=15.12)) is None
    assert compare(_with(WP, z=15.2), _with(WP, z=15.12)).field == "z"  # type: ignore[union-attr]


def test_a_nan_param_accepts_whatever_comes_back():
    takeoff = MissionItem(22, 3, 0, 0, 0, NAN, 1, 1, 20)
    for back in (0.0, 90.0, NAN):
        assert compare(takeoff, _with(takeoff, param4=back)) is None
    unknown = MissionItem(31000, 2, NAN, 1, 2, 3)
    assert compare(unknown, _with(unknown, param1=7.0)) is None


def test_params_ardupilot_does_not_keep_accept_zero():
    assert compare(_with(WP, param2=2.0, param4=90.0), _with(WP, param2=0.0, param4=0.0)) is None
    land = MissionItem(21, 3, 0, 0, 0, 0, 1, 1, 0)
    assert compare(land, _with(land, param4=1.0)) is None  # back as the direction +1
    takeoff = MissionItem(22, 3, 0, 0, 0, 0, 1, 1, 20)
    assert compare(takeoff, _with(takeoff, param4=0.0)) is None


def test_params_kept_in_integer_fields_match_their_truncation():
    assert compare(_with(WP, param1=2.5), _with(WP, param1=2.0)) is None  # ArduPilot's uint16
    assert compare(_with(WP, param1=2.5), _with(WP, param1=2.5)) is None  # PX4's float
    assert compare(_with(WP, param1=2.5), _with(WP, param1=3.0)).field == "param1"  # type: ignore[union-attr]
    jump = MissionItem(177, 2, 3, 2)
    assert compare(jump, _with(jump, param2=1.0)).field == "param2"  # type: ignore[union-attr]


def test_float_params_match_as_float32():
    speed = MissionItem(178, 2, 1.0, 5.1, -1.0, 0.0)
    assert compare(speed, _with(speed, param2=5.1 + 1e-8)) is None
    assert compare(speed, _with(speed, param2=6.0)).field == "param2"  # type: ignore[union-attr]
    assert compare(speed, _with(speed, param2=NAN)).field == "param2"  # type: ignore[union-attr]
    assert "sent 5.1, read back 6.0" in str(compare(speed, _with(speed, param2=6.0)))


def test_autocontinue_is_not_compared():
    assert compare(_with(WP, autocontinue=0), WP) is None  # ArduPilot always answers 1


def test_the_qgc_square_with_nulls_survives_ardupilots_storage():
    """Issue 13: the QGC plan's null yaws came back 0 and failed verification at item 0."""
    plan = [
        {"command": 22, "frame": 3, "params": [0, 0, 0, None], "lat": 47.397742, "lon": 8.545594, "alt": 20},
        {"command": 178, "frame": 2, "params": [1, 5, -1, 0], "lat": 0, "lon": 0, "alt": 0},
        *({"command": 16, "frame": 3, "params": [0, 0, 0, None], "lat": 47.398742, "lon": lon,
           "alt": 20} for lon in (8.546594, 8.544594)),
        {"command": 21, "frame": 3, "params": [0, 0, 0, 0], "lat": 0, "lon": 0, "alt": 0},
        {"command": 20, "frame": 2, "params": [0, 0, 0, 0], "lat": 0, "lon": 0, "alt": 0},
        {"command": 19, "frame": 6, "params": [10.7, 0, 15, None], "lat": 47.39, "lon": 8.54, "alt": 31.337},
    ]  # fmt: skip
    for item in items_from_dicts(plan):
        assert compare(item, _as_sim_stores(item)) is None, item


@pytest.mark.parametrize("code", sorted(MAV_MISSION_RESULT_NAMES))
def test_every_mission_ack_result_reads_as_a_sentence(code: int):
    text = mission_result_text(code)
    name, _, sentence = text.partition(": ")
    assert name == MAV_MISSION_RESULT_NAMES[code] and len(sentence) > 10
    assert "does not know" in mission_result_text(99)
