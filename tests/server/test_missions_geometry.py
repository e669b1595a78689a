"""Missions, pure geometry: distances, projection, polygons, the lawnmower compiler, flight estimates."""

from __future__ import annotations

import math

from hypothesis import given, settings
from hypothesis import strategies as st

from server.missions.flight import estimate_flight
from server.missions.geometry import (
    LocalProjection,
    distinct_points,
    haversine_m,
    ring_area,
    scanline,
    segments_intersect,
    self_intersections,
)
from server.missions.items import MissionItem
from server.missions.survey import Camera, SurveySpec, best_heading, compile_survey, lawnmower
from server.missions.validate import (
    FlightModel,
    Home,
    MissionLimits,
    check_endurance,
    validate_items,
    validate_ring,
)

# a 200 m x 200 m square near Zurich (lon, lat), closed as GeoJSON writes it
LAT0, LON0 = 47.3977, 8.5456
DLAT = 200 / 111_195.0
DLON = 200 / (111_195.0 * math.cos(math.radians(LAT0)))
SQUARE = (
    (LON0, LAT0),
    (LON0 + DLON, LAT0),
    (LON0 + DLON, LAT0 + DLAT),
    (LON0, LAT0 + DLAT),
    (LON0, LAT0),
)


def test_haversine_matches_known_distances():
    # one degree of latitude on the mean sphere, and Zurich -> Geneva (~224 km)
    assert abs(haversine_m(0, 0, 1, 0) - 111_195.08) < 1
    assert abs(haversine_m(47.3769, 8.5417, 46.2044, 6.1432) - 224_100) < 1500
    assert haversine_m(LAT0, LON0, LAT0, LON0) == 0


def test_local_projection_round_trips_and_agrees_with_haversine():
    proj = LocalProjection(LAT0, LON0)
    x, y = proj.to_local(LAT0 + 0.01, LON0 + 0.01)
    lat, lon = proj.to_geo(x, y)
    assert abs(lat - (LAT0 + 0.01)) < 1e-12 and abs(lon - (LON0 + 0.01)) < 1e-12
    assert abs(math.hypot(x, y) - haversine_m(LAT0, LON0, LAT0 + 0.01, LON0 + 0.01)) < 1.0
    # across the antimeridian the short way round
    p = LocalProjection(0, 179.999)
    assert abs(p.to_local(0, -179.999)[0] - 222.4) < 1


def test_area_distinct_points_and_self_intersection():
    square = [(0, 0), (10, 0), (10, 10), (0, 10), (0, 0)]
    assert ring_area(square) == 100 and ring_area(list(reversed(square))) == -100
    assert distinct_points(square) == 4 and distinct_points([(0, 0), (1, 1), (0, 0), (1, 1)]) == 2
    assert self_intersections(square) == []
    bowtie = [(0, 0), (10, 10), (10, 0), (0, 10)]
    assert self_intersections(bowtie) == [(0, 2)]
    # a spike folding back along itself, and a ring touching itself at a vertex
    assert self_intersections([(0, 0), (10, 0), (5, 0), (5, 5)])
    assert self_intersections([(0, 0), (4, 0), (2, 2), (4, 4), (0, 4), (2, 2)])
    assert segments_intersect((0, 0), (2, 0), (1, 0), (3, 0))  # collinear overlap
    assert not segments_intersect((0, 0), (1, 0), (0, 1), (1, 1))


def test_scanline_spans_of_a_concave_ring():
    u = [(0, 0), (30, 0), (30, 20), (20, 20), (20, 5), (10, 5), (10, 20), (0, 20)]
    assert scanline(u, 2) == [(0, 30)]
    assert scanline(u, 10) == [(0, 10), (20, 30)]
    assert scanline(u, 25) == []


def test_polygon_validation_names_each_problem():
    limits = MissionLimits()
    assert validate_ring(SQUARE, limits) == []
    assert validate_ring([], limits)[0].what == "the polygon is empty"
    two = validate_ring([(LON0, LAT0), (LON0 + DLON, LAT0), (LON0, LAT0)], limits)
    assert two[0].what.startswith("a polygon needs at least 3") and two[0].value == 2
    bow = validate_ring(
        [(LON0, LAT0), (LON0 + DLON, LAT0 + DLAT), (LON0 + DLON, LAT0), (LON0, LAT0 + DLAT)], limits
    )
    assert any("intersects itself" in p.what for p in bow)
    big = [
        (LON0, LAT0),
        (LON0 + 20 * DLON, LAT0),
        (LON0 + 20 * DLON, LAT0 + 20 * DLAT),
        (LON0, LAT0 + 20 * DLAT),
    ]
    too_large = validate_ring(big, limits)
    assert too_large[0].what.startswith("the area is too large") and too_large[0].limit == 4_000_000
    assert abs(too_large[0].value - 16_000_000) < 50_000
    assert (
        validate_ring(big, MissionLimits(max_area_m2=20_000_000)) == []
    )  # the limit is configurable
    out = validate_ring([(LON0, 91.0), (LON0, LAT0), (LON0 + 1, LAT0)], limits)
    assert out[0].where == "survey.polygon.coordinates[0][0].lat" and out[0].value == 91.0


def test_item_validation_altitude_frames_commands_and_jumps():
    limits = MissionLimits()
    items = [
        MissionItem(command=22, alt=20),
        MissionItem(command=16, lat=47.4, lon=8.5, alt=150),  # too high
        MissionItem(command=16, lat=47.4, lon=8.5, alt=1),  # too low
        MissionItem(command=84, frame=2),  # NAV_VTOL_TAKEOFF: not for a copter
        MissionItem(
            command=16, frame=2, lat=47.4, lon=8.5, alt=20
        ),  # a waypoint needs a global frame
        MissionItem(command=16, lat=95, lon=8.5, alt=20),
        MissionItem(command=177, frame=2, params=(99, 1, 0, 0)),  # DO_JUMP to nowhere
        MissionItem(command=21, lat=47.4, lon=8.5, alt=0),  # landing at 0 m is fine
        MissionItem(
            command=16, frame=0, lat=47.4, lon=8.5, alt=600
        ),  # AMSL: 100 m above a 500 m home
    ]
    problems = validate_items(items, limits, Home(47.4, 8.5, 500))
    where = [(p.where, p.index, p.command) for p in problems]
    assert where == [
        ("items[1].alt", 1, 16),
        ("items[2].alt", 2, 16),
        ("items[3].command", 3, 84),
        ("items[4].frame", 4, 16),
        ("items[5].lat", 5, 16),
        ("items[6].params[0]", 6, 177),
    ]
    assert problems[0].value == 150 and problems[0].limit == 120
    assert problems[1].value == 1 and problems[1].limit == 2
    assert "NAV_VTOL_TAKEOFF" in problems[2].what
    assert validate_items(items[:1], MissionLimits(max_alt_m=10))[0].limit == 10


def test_lawnmower_over_a_square_north_south():
    proj = LocalProjection(LAT0 + DLAT / 2, LON0 + DLON / 2)
    local = [proj.to_local(lat, lon) for lon, lat in SQUARE[:-1]]
    segments = lawnmower(local, 0.0, 30.0)
    assert len(segments) == 7  # ceil(200 / 30)
    xs = [a[0] for a, _ in segments]
    assert all(abs(abs(xs[k + 1] - xs[k]) - 30.0) < 1e-6 for k in range(6))
    assert abs((xs[0] + xs[-1]) / 2) < 1e-6  # centred on the area
    # boustrophedon: alternate north / south, each line spanning the square
    for k, (a, b) in enumerate(segments):
        assert abs(abs(b[1] - a[1]) - 200) < 0.5
        assert (b[1] > a[1]) == (k % 2 == 0)


def test_compiled_survey_items_and_footprint():
    camera = Camera(13.2, 8.8, 8.8, 5472, 3648)  # a 1" sensor, 8.8 mm lens
    width, height = camera.footprint(50)
    assert (width, height) == (75.0, 50.0)
    assert abs(camera.gsd_cm(50) - 1.3706) < 1e-3
    spec = SurveySpec(SQUARE, width, height, 70, 60, 50, 6.0, heading_deg=90)
    assert spec.line_spacing_m == 30 and abs(spec.trigger_distance_m - 15) < 1e-9
    plan = compile_survey(spec)
    assert len(plan.lines) == 7 and plan.heading_deg == 90
    commands = [i.command for i in plan.items]
    assert commands[:2] == [22, 178] and commands[-1] == 20
    assert commands[2:-1] == [16, 206, 16, 206] * 7
    assert (
        plan.items[1].params[1] == 6.0
        and plan.items[3].params[0] == 15.0
        and plan.items[5].params[0] == 0
    )
    assert all(i.alt == 50 for i in plan.items if i.command in (16, 22))
    # east-west lines: each at one latitude, inside the square
    for a, b in plan.lines:
        assert abs(a[0] - b[0]) < 1e-7 and LAT0 < a[0] < LAT0 + DLAT


def test_best_heading_follows_the_long_side():
    # a 600 m x 100 m strip, long side east-west: lines should run east-west (90°)
    proj = LocalProjection(LAT0, LON0)
    local = [(0, 0), (600, 0), (600, 100), (0, 100)]
    assert best_heading(local, 30) == 90.0
    del proj


@st.composite
def convex_polygons(draw):
    n = draw(st.integers(3, 9))
    radius = draw(st.floats(40, 800))
    angles = sorted(
        draw(
            st.lists(
                st.floats(0, 2 * math.pi, exclude_max=True), min_size=n, max_size=n, unique=True
            )
        )
    )
    pts = [(radius * math.cos(a), radius * math.sin(a)) for a in angles]
    if abs(ring_area(pts)) < 100:
        pts = [(0, 0), (100, 0), (0, 100)]
    return pts


def _inside(pts, p, tol=0.01):
    """Point in (or within tol of) a convex counter-clockwise ring."""
    for i in range(len(pts)):
        (x1, y1), (x2, y2) = pts[i], pts[(i + 1) % len(pts)]
        cross = (x2 - x1) * (p[1] - y1) - (y2 - y1) * (p[0] - x1)
        if cross < -tol * math.hypot(x2 - x1, y2 - y1):
            return False
    return True


@settings(max_examples=60, deadline=None)
@given(convex_polygons(), st.floats(0, 180, exclude_max=True), st.floats(5, 60))
def test_lawnmower_stays_inside_and_covers_the_area(pts, heading, spacing):
    segments = lawnmower(pts, heading, spacing)
    assert segments
    for a, b in segments:
        assert _inside(pts, a) and _inside(pts, b)
    # the lines are spacing apart across the heading, and together they span the area's width
    across = (math.cos(math.radians(heading)), -math.sin(math.radians(heading)))
    offsets = sorted({round(a[0] * across[0] + a[1] * across[1], 6) for a, _ in segments})
    for k in range(len(offsets) - 1):
        assert abs(offsets[k + 1] - offsets[k] - spacing) < 1e-3
    span = [p[0] * across[0] + p[1] * across[1] for p in pts]
    assert len(offsets) * spacing >= (max(span) - min(span)) - 1e-6


def test_flight_estimate_walks_speeds_loiters_and_jumps():
    model = FlightModel(
        climb_mps=2.0, descent_mps=1.0, per_waypoint_s=0.0, takeoff_s=0.0, landing_s=0.0
    )
    east = LON0 + 1000 / (111_195.0 * math.cos(math.radians(LAT0)))
    items = [
        MissionItem(command=22, alt=20),
        MissionItem(command=16, lat=LAT0, lon=east, alt=20),
        MissionItem(command=20, frame=2),
    ]
    est = estimate_flight(items, 10.0, Home(LAT0, LON0, 400), model)
    # climb 20 m (10 s), 1000 m out (100 s), 1000 m back (100 s), descend 20 m (20 s)
    assert abs(est.distance_m - 2040) < 2 and abs(est.flight_time_s - 230) < 0.5 and not est.endless
    faster = [items[0], MissionItem(command=178, frame=2, params=(1, 20, -1, 0)), *items[1:]]
    assert (
        abs(estimate_flight(faster, 10.0, Home(LAT0, LON0, 400), model).flight_time_s - 130) < 0.5
    )
    loiter = [
        *items[:2],
        MissionItem(command=19, lat=LAT0, lon=east, alt=20, params=(60, 0, 0, 0)),
        items[2],
    ]
    assert (
        abs(estimate_flight(loiter, 10.0, Home(LAT0, LON0, 400), model).flight_time_s - 290) < 0.5
    )
    # DO_JUMP back to the waypoint (seq 2) twice more: two extra legs of 0 m, then 1000 m home
    jump = [
        *items[:2],
        MissionItem(command=16, lat=LAT0, lon=LON0, alt=20),
        MissionItem(command=177, frame=2, params=(2, 2, 0, 0)),
        items[2],
    ]
    est_jump = estimate_flight(jump, 10.0, Home(LAT0, LON0, 400), model)
    assert abs(est_jump.distance_m - (40 + 6 * 1000)) < 5
    endless = estimate_flight([items[0], MissionItem(command=17, lat=LAT0, lon=LON0, alt=20)], 10.0)
    assert endless.endless and "NAV_LOITER_UNLIM" in endless.note
    forever = estimate_flight(
        [*items[:2], MissionItem(command=177, frame=2, params=(1, -1, 0, 0))], 10.0
    )
    assert forever.endless


def test_endurance_check_keeps_a_reserve():
    model = FlightModel()
    items = [MissionItem(command=22, alt=20), MissionItem(command=21, lat=LAT0, lon=LON0)]
    est = estimate_flight(items, 8.0, Home(LAT0, LON0, 0), model)
    assert check_endurance(est, 1200) == []
    assert check_endurance(est, est.flight_time_s / 0.79) == []
    problems = check_endurance(est, est.flight_time_s / 0.81)
    assert problems and problems[0].limit == round(est.flight_time_s / 0.81 * 0.8, 1)


def test_delays_count_in_the_estimate_and_roi_may_use_the_mission_frame():
    model = FlightModel(per_waypoint_s=0.0, takeoff_s=0.0, landing_s=0.0)
    base = [MissionItem(command=22, alt=20), MissionItem(command=21, lat=LAT0, lon=LON0)]
    delayed = [
        base[0],
        MissionItem(command=93, frame=2, params=(30, -1, -1, -1)),
        MissionItem(command=112, frame=2, params=(15, 0, 0, 0)),
        base[1],
    ]
    t0 = estimate_flight(base, 8.0, Home(LAT0, LON0, 0), model).flight_time_s
    t1 = estimate_flight(delayed, 8.0, Home(LAT0, LON0, 0), model).flight_time_s
    assert abs(t1 - t0 - 45) < 1e-6
    roi = [base[0], MissionItem(command=201, frame=2, params=(0, 0, 0, 0)), base[1]]
    assert validate_items(roi, MissionLimits()) == []


def test_compiled_items_are_what_the_agent_and_the_simulated_autopilot_accept():
    """Contract: the agent's parser takes every compiled item; the simulator stores them."""
    from asset_agent.autopilot.items import items_from_dicts
    from server.missions.items import item_dicts
    from sim.vehicle import mission as sim_mission

    spec = SurveySpec(SQUARE, 75, 50, 70, 60, 50, 6.0, heading_deg=30, camera_trigger=False)
    items = item_dicts(list(compile_survey(spec).items))
    converted = items_from_dicts(items)
    assert len(converted) == len(items) == 2 + 2 * len(compile_survey(spec).lines) + 1
    for seq, it in enumerate(converted, start=1):
        stored = sim_mission.Item(
            seq,
            it.frame,
            it.command,
            it.param1,
            it.param2,
            it.param3,
            it.param4,
            it.x,
            it.y,
            it.z,
            it.autocontinue,
        )
        assert sim_mission.validate(stored) == sim_mission.ACCEPTED, (seq, it)
    with_trigger = item_dicts(
        list(compile_survey(SurveySpec(SQUARE, 75, 50, 70, 60, 50, 6.0)).items)
    )
    assert items_from_dicts(with_trigger)[3].command == 206


def test_limits_come_from_settings_when_they_carry_them():
    from types import SimpleNamespace

    from server.missions.service import limits_from

    assert limits_from(SimpleNamespace()) == MissionLimits()
    custom = limits_from(SimpleNamespace(mission_max_alt_m=60, mission_max_area_m2=1e6))
    assert custom.max_alt_m == 60 and custom.max_area_m2 == 1e6 and custom.min_alt_m == 2
