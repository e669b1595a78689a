"""The precision-landing supervisor's pure parts: when it is active, the pad prior's offset."""

from __future__ import annotations

import math
from dataclasses import replace
from types import MappingProxyType, SimpleNamespace

import pytest

from asset_agent.autopilot.flight_state import infer_landed_state
from asset_agent.autopilot.state import UavState
from asset_agent.config import PreclandSection
from asset_agent.events import Event
from asset_agent.precland.report import PadFix, pad_offset_ned
from asset_agent.precland.supervisor import (
    ATTITUDE,
    EXTENDED_SYS_STATE,
    LOCAL_POSITION_NED,
    PrecisionLander,
    descending,
    landing_now,
    stream_rates,
)


def state(**changes: object) -> SimpleNamespace:
    """An armed autopilot in a mission's final descent at 5 m."""
    base = dict(armed=True, landed_state="LANDING", mode="AUTO", in_air=True, alt_rel=5.0)
    return SimpleNamespace(**{**base, **changes})


@pytest.mark.parametrize(
    ("changes", "lands"),
    [
        ({}, True),
        ({"landed_state": "IN_AIR", "mode": "LAND"}, True),  # LAND mode before the state says so
        ({"landed_state": "IN_AIR"}, False),
        ({"landed_state": "ON_GROUND", "mode": "LAND", "in_air": False}, False),
        ({"armed": False}, False),
    ],
)
def test_descending_means_armed_and_landing(changes: dict[str, object], lands: bool) -> None:
    assert descending(state(**changes)) is lands


def test_active_only_below_the_activation_height() -> None:
    assert landing_now(state(alt_rel=5.0), 8.0)
    assert not landing_now(state(alt_rel=9.0), 8.0)
    assert not landing_now(state(alt_rel=None), 8.0)
    assert not landing_now(state(alt_rel=5.0, armed=False), 8.0)


def test_pad_offset_is_north_east_metres() -> None:
    dn, de = pad_offset_ned(47.0, 8.0, 47.0 + 1e-5, 8.0 + 1e-5)
    assert dn == pytest.approx(1.113, abs=1e-3)
    assert de == pytest.approx(1.113 * math.cos(math.radians(47.0)), abs=1e-3)


def test_stream_rates_ask_for_the_states_the_loop_needs() -> None:
    section = PreclandSection()
    rates = stream_rates(section)
    assert set(rates) == {ATTITUDE, LOCAL_POSITION_NED, EXTENDED_SYS_STATE}
    assert rates[ATTITUDE] == section.state_rate_hz


def test_an_autopilot_without_extended_state_activates_it_by_the_inferred_landing() -> None:
    # ArduPilot 3.7 sends no EXTENDED_SYS_STATE: the landed state the adapter infers drives the
    # supervisor, through an RTL as the run flies it (climb, return, final descent over home)
    home = (41.178, -8.596)
    north = 1.0 / 111_320  # degrees per metre
    flight = [  # (mode, metres north of home, height, vd, active?)
        ("AUTO", 60.0, 6.0, 0.0, False),  # surveying low
        ("RTL", 60.0, 7.0, -2.0, False),  # climbing to RTL_ALT
        ("RTL", 30.0, 7.0, 1.0, False),  # a descent on the way home, below the activation height
        ("RTL", 0.5, 15.0, 0.0, False),  # over home, loitering
        ("RTL", 0.5, 12.0, 1.5, False),  # final descent, above the activation height
        ("RTL", 0.3, 7.0, 1.0, True),  # ... below it
        ("RTL", 0.2, 4.0, 0.05, True),  # descent held (off the target): still landing
    ]
    landed = "IN_AIR"
    for mode, north_m, height, vd, active in flight:
        s = UavState(
            link_up=True, armed=True, system_status=4, mode=mode, alt_rel=height, vd=vd,
            lat=home[0] + north_m * north, lon=home[1], home_lat=home[0], home_lon=home[1],
        )  # fmt: skip
        landed = infer_landed_state(landed, s)
        s = replace(s, landed_state=landed)
        assert landing_now(s, 8.0) is active, (mode, north_m, height, vd, landed)


def test_the_landed_event_says_which_way_the_landing_went() -> None:
    lander = PrecisionLander(SimpleNamespace(), PreclandSection())
    landed = Event("landed", MappingProxyType({"lat": 41.0, "lon": -8.0}))
    detail = lander.with_touchdown(landed).detail
    assert detail == {"lat": 41.0, "lon": -8.0, "offset_source": "none", "landing_path": "gnss"}
    lander.last_fix = PadFix(0.0, (0.012, -0.005, 0.4), ("aruco", "ir"))
    detail = lander.with_touchdown(landed).detail
    assert detail["landing_path"] == "precision" and detail["offset_source"] == "precland"
    assert detail["offset_m"] == 0.013 and detail["fix_sources"] == "aruco+ir"
