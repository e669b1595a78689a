"""The zones of a flight as the fence ArduPilot takes (server/airspace/fence.py). Pure."""

from __future__ import annotations

import math

from server.airspace.check import ZoneShape
from server.airspace.fence import MAX_VERTICES, build_fence, simplify_ring
from server.missions.geometry import LocalProjection
from server.missions.items import items_of
from server.missions.validate import Home

HOME = Home(47.3977, 8.5456, 488.0)
PROJ = LocalProjection(HOME.lat, HOME.lon)


def ring(*corners: tuple[float, float]) -> tuple[tuple[float, float], ...]:
    """(lon, lat) of (east, north) metres from home."""
    return tuple((lon, lat) for lat, lon in (PROJ.to_geo(e, n) for e, n in corners))


def wp(east: float, north: float, command: int = 16) -> dict:
    lat, lon = PROJ.to_geo(east, north)
    return {"command": command, "frame": 3, "lat": lat, "lon": lon, "alt": 30}


ITEMS = items_of([wp(0, 0, 22), wp(200, 0), {"command": 20, "frame": 2}])


def test_a_zone_the_path_flies_over_is_left_to_the_server_check():
    over = ZoneShape(
        "o", "low shed", "exclusion", ring((90, -10), (110, -10), (110, 10), (90, 10)), ceiling_m=20
    )
    aside = ZoneShape("a", "mast", "exclusion", center=PROJ.to_geo(100, 50), radius_m=10)
    fence = build_fence(ITEMS, HOME, [over, aside])
    assert fence.left_to_the_server == ["low shed"]
    assert [i["command"] for i in fence.items] == [5004, 5000]  # the mast, then the return point
    assert fence.items[0]["params"][0] == 10 and fence.alt_max_m is None


def test_ceilings_become_fence_alt_max_and_amsl_is_converted():
    a = ZoneShape(
        "a", "area", "inclusion", center=(HOME.lat, HOME.lon), radius_m=500, ceiling_m=120
    )
    b = ZoneShape(
        "b", "ctr", "inclusion", center=(HOME.lat, HOME.lon), radius_m=900, ceiling_m=588, amsl=True
    )
    assert build_fence(ITEMS, HOME, [a, b]).alt_max_m == 100.0


def test_a_polygon_over_the_autopilots_limit_is_simplified_close_to_its_boundary():
    circle = [
        (300 * math.cos(2 * math.pi * k / 400), 300 * math.sin(2 * math.pi * k / 400))
        for k in range(400)
    ]
    simple = simplify_ring(circle)
    assert 3 <= len(simple) <= MAX_VERTICES
    worst = max(min(math.dist(p, q) for q in simple) for p in circle)
    assert worst < 20  # no drawn vertex far from the simplified one
    zone = ZoneShape("c", "round", "inclusion", ring(*circle))
    fence = build_fence(ITEMS, HOME, [zone])
    vertices = [i for i in fence.items if i["command"] == 5001]
    assert len(vertices) == len(simple) and all(i["params"][0] == len(simple) for i in vertices)


def test_a_breach_in_flight_sends_the_run_home_with_an_alert_and_airspace_refuses_the_check():
    from server.runs.machine import Observations, State, advance

    flying = Observations(elapsed_s=5, timeout_s=100, commands={}, uav_events=("fence_breach",))
    t = advance(State.flying, flying)
    assert t is not None and t.to == State.landing and t.cause == "fence_breach" and t.alert
    checking = Observations(
        elapsed_s=1,
        timeout_s=60,
        commands={},
        airspace="segment items[1]→items[2] enters exclusion zone 'h' for 60.0 m",
    )
    t = advance(State.checking, checking)
    assert t is not None and t.to == State.aborted and t.cause == "airspace"
    assert "items[1]→items[2]" in t.reason
