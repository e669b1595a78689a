"""The precision-landing supervisor's pure parts: when it is active, the pad prior's offset."""

from __future__ import annotations

import math
from types import SimpleNamespace

import pytest

from asset_agent.config import PreclandSection
from asset_agent.precland.supervisor import (
    ATTITUDE,
    EXTENDED_SYS_STATE,
    LOCAL_POSITION_NED,
    descending,
    landing_now,
    pad_offset_ned,
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
