"""The agent's telemetry from the autopilot's state: NaN from the autopilot is dropped field by field
(issue 14, item 10: a NaN attitude once made every whole sample refused)."""

from __future__ import annotations

import logging
import math
from types import MappingProxyType

import pytest
from pymavlink.dialects.v20 import ardupilotmega as mavlink2

from asset_agent.autopilot.state import UavState
from asset_agent.autopilot.translate import apply
from asset_agent.events import Event
from asset_agent.uav_telemetry import to_event, to_telemetry
from protocol.codec import decode, encode
from protocol.messages import Telemetry, envelope


def test_non_finite_autopilot_values_are_dropped_and_the_rest_is_sent() -> None:
    state = UavState(
        link_up=True, lat=41.0, lon=-8.6, alt_msl=120.0, alt_rel=math.nan,
        roll_deg=math.nan, pitch_deg=1.0, yaw_deg=2.0, heading_deg=math.inf,
        vn=0.0, ve=0.0, vd=0.0, battery_pct=math.nan, voltage_v=16.0, current_a=-math.inf,
        hdop=math.nan, armed=True,
    )  # fmt: skip
    sample = to_telemetry(state)
    assert sample.attitude is None and sample.heading_deg is None
    assert sample.position is not None and sample.position.lat == 41.0
    assert sample.velocity is not None and sample.armed
    assert sample.battery is not None and sample.battery.voltage_v == 16.0
    assert sample.battery.percent is None and sample.battery.current_a is None
    text = encode(envelope(sample, seq=1))
    assert isinstance(decode(text, "asset_to_server"), Telemetry)


def test_non_finite_event_details_are_dropped() -> None:
    event = Event("waypoint_reached", MappingProxyType({"index": 3, "dist": math.nan, "x": 1.5}))
    assert to_event(event).data == {"index": 3, "number": 4, "x": 1.5}


def test_an_out_of_range_autopilot_value_leaves_out_its_part_alone_and_warns_once(
    caplog: pytest.LogCaptureFixture,
) -> None:
    """Issue 48 finding 7: a GLOBAL_POSITION_INT with a latitude of 200° (its int32 carries it)
    through the translate layer leaves the position out; the rest of the sample is sent, and
    the agent's log has one warning with no traceback, however many such samples follow."""
    mav = mavlink2.MAVLink(None)
    state = UavState(link_up=True, voltage_v=16.0, battery_pct=80.0, satellites=12, armed=True)
    state = apply(state, mav.attitude_encode(0, 0.1, 0.2, 0.3, 0, 0, 0))
    good = mav.global_position_int_encode(0, 411_000_000, -86_000_000, 120_000, 20_000, 100, 0, 0, 9000)  # fmt: skip
    bad = mav.global_position_int_encode(0, 2_000_000_000, -86_000_000, 120_000, 20_000, 100, 0, 0, 9000)  # fmt: skip
    with caplog.at_level(logging.INFO, logger="asset_agent.uav_telemetry"):
        samples = [to_telemetry(apply(state, m)) for m in (good, bad, bad, bad, good)]
    assert [s.position is not None for s in samples] == [True, False, False, False, True]
    for sample in samples[1:4]:  # the rest of the sample is there
        assert sample.velocity is not None and sample.velocity.north_m_s == 1.0
        assert sample.attitude is not None and sample.heading_deg == 90.0
        assert sample.battery is not None and sample.battery.voltage_v == 16.0
        assert sample.gnss is not None and sample.gnss.satellites == 12 and sample.armed
        text = encode(envelope(sample, seq=1))
        assert isinstance(decode(text, "asset_to_server"), Telemetry)
    warnings = [r for r in caplog.records if r.levelno == logging.WARNING]
    assert len(warnings) == 1 and warnings[0].exc_info is None, caplog.text
    assert "position" in warnings[0].getMessage() and "200" in warnings[0].getMessage()
    assert any("in range again" in r.getMessage() for r in caplog.records)
