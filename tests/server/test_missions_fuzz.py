"""Missions, file formats under random input: readers never crash, round trips never lose items."""

from __future__ import annotations

import copy
import json

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from server.missions.items import COMMANDS, MissionItem
from server.missions.qgc import ImportRejected, parse_plan
from server.missions.qgc_export import export_plan
from server.missions.validate import Home
from server.missions.wpl import HEADER, export_wpl, parse_wpl
from tests.server.test_missions_formats import wrap


@settings(max_examples=150, deadline=None)
@given(
    st.recursive(
        st.none() | st.booleans() | st.integers() | st.floats() | st.text(max_size=5),
        lambda c: st.lists(c, max_size=4) | st.dictionaries(st.text(max_size=8), c, max_size=4),
        max_leaves=30,
    )
)
def test_arbitrary_json_never_crashes_the_plan_reader(document):
    for doc in (
        document,
        wrap([document]),
        wrap([{"type": "SimpleItem", **document}])
        if isinstance(document, dict)
        else wrap([document]),
    ):
        try:
            parse_plan(copy.deepcopy(doc))
        except ImportRejected as err:
            assert err.problems


@settings(max_examples=150, deadline=None)
@given(st.text(max_size=300))
def test_arbitrary_text_never_crashes_the_wpl_reader(text):
    for doc in (
        text,
        f"{HEADER}\n{text}",
        f"{HEADER}\n0\t1\t0\t16\t0\t0\t0\t0\t1\t2\t3\t1\n1 {text}",
    ):
        try:
            parse_wpl(doc)
        except ImportRejected as err:
            assert err.problems


finite = st.floats(-1e6, 1e6, allow_nan=False)


@st.composite
def missions(draw):
    """Random lists of supported items, with valid DO_JUMP targets."""
    n = draw(st.integers(1, 12))
    out = []
    for _ in range(n):
        command = draw(st.sampled_from(sorted(COMMANDS)))
        spec = COMMANDS[command]
        frame = draw(st.sampled_from([0, 3, 10] if spec.nav and spec.positional else [0, 2, 3, 10]))
        params = tuple(draw(st.one_of(st.none(), finite)) for _ in range(4))
        if command == 177:
            params = (float(draw(st.integers(1, n))), float(draw(st.integers(-1, 5))), 0.0, 0.0)
        out.append(
            MissionItem(
                command=command,
                frame=frame,
                params=params,
                lat=draw(st.floats(-90, 90)),
                lon=draw(st.floats(-180, 180)),
                alt=draw(st.floats(-1000, 10000)),
                autocontinue=draw(st.booleans()),
            )
        )
    return out


@settings(max_examples=100, deadline=None)
@given(
    missions(),
    st.one_of(
        st.none(), st.builds(Home, st.floats(-89, 89), st.floats(-179, 179), st.floats(-100, 5000))
    ),
)
@pytest.mark.slow
def test_round_trips_are_lossless_for_any_supported_mission(items, home):
    # a .plan refuses the terrain frame (no terrain data to check it against): relative instead
    flat = [
        i.model_copy(update={"frame": 3}) if i.spec and i.spec.positional and i.frame == 10 else i
        for i in items
    ]
    plan = parse_plan(json.loads(json.dumps(export_plan(flat, home, 5.0))))
    assert plan.items == flat
    again = parse_plan(json.loads(json.dumps(export_plan(plan.items, plan.home, 5.0, plan.extras))))
    assert again.items == flat and again.extras == plan.extras
    if home is not None:
        assert plan.home == home
    text = parse_wpl(export_wpl(items, home))
    assert text.items == items
    if home is not None and (home.lat, home.lon) != (0.0, 0.0):
        assert text.home == home


ALTITUDE_VALUES = st.one_of(
    st.none(),
    st.integers(-2, 6),
    st.floats(allow_nan=True, allow_infinity=True),
    st.text(max_size=3),
    st.booleans(),
    st.lists(st.integers(), max_size=2),
)


@settings(max_examples=200, deadline=None)
@given(
    st.sampled_from([16, 21, 22, 82, 195, 201]),
    st.sampled_from([0, 2, 3, 5, 6, 10, 11]),
    st.dictionaries(
        st.sampled_from(["AltitudeMode", "Altitude", "AMSLAltAboveTerrain"]), ALTITUDE_VALUES
    ),
    st.one_of(st.none(), st.floats(-100, 1000)),
    st.one_of(st.none(), st.floats(-90, 90)),
)
def test_any_altitude_keys_are_taken_or_refused_by_item(command, frame, keys, alt, lat):
    raw = {
        "type": "SimpleItem",
        "command": command,
        "frame": frame,
        "params": [0, 0, 0, None, lat, 8.5, alt],
        "autoContinue": True,
        "doJumpId": 2,
        **keys,
    }
    takeoff = {
        "type": "SimpleItem",
        "command": 22,
        "frame": 3,
        "params": [0, 0, 0, None, 47, 8, 20],
        "autoContinue": True,
        "doJumpId": 1,
    }
    try:
        imported = parse_plan(wrap([takeoff, raw]))
    except ImportRejected as err:
        assert err.problems and all(p.index == 1 for p in err.problems)
    else:
        # nothing null was read as a number, and no terrain frame got through
        wp = imported.items[1]
        assert alt is not None and wp.alt == alt and wp.frame != 10
