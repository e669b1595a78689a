"""The plan's speed reaches the UAV as a DO_CHANGE_SPEED item (issue 13: a 5 m/s plan flew at 10 m/s)."""

from __future__ import annotations

from server.missions.build import flight_items

TAKEOFF = {"command": 22, "frame": 3, "params": [0, 0, 0, None], "lat": 1, "lon": 2, "alt": 20}
WP = {"command": 16, "frame": 3, "params": [0, 0, 0, None], "lat": 1.001, "lon": 2, "alt": 20}


def test_the_speed_goes_right_after_the_takeoff_as_a_ground_speed():
    out = flight_items([TAKEOFF, WP, WP], 5.0)
    assert [i["command"] for i in out] == [22, 178, 16, 16]
    speed = out[1]
    assert speed["params"] == [1.0, 5.0, -1.0, 0.0]  # ground speed, 5 m/s, throttle unchanged
    assert speed["frame"] == 2


def test_without_a_takeoff_the_speed_goes_first():
    assert [i["command"] for i in flight_items([WP, WP], 3.5)] == [178, 16, 16]


def test_no_speed_or_a_speed_already_set_leaves_the_items_as_they_are():
    assert flight_items([TAKEOFF, WP], None) == [TAKEOFF, WP]
    assert flight_items([TAKEOFF, WP], 0) == [TAKEOFF, WP]
    own = {"command": 178, "frame": 2, "params": [1, 8, -1, 0], "lat": 0, "lon": 0, "alt": 0}
    delay = {"command": 112, "frame": 2, "params": [2, 0, 0, 0], "lat": 0, "lon": 0, "alt": 0}
    assert flight_items([TAKEOFF, delay, own, WP], 5.0) == [TAKEOFF, delay, own, WP]
    # a speed change later in the mission is not the mission's speed: ours still goes first
    assert [i["command"] for i in flight_items([TAKEOFF, WP, own], 5.0)] == [22, 178, 16, 178]
