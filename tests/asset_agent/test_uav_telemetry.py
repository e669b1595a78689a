"""The agent's telemetry from the autopilot's state: NaN from the autopilot is dropped field by field
(issue 14, item 10: a NaN attitude once made every whole sample refused)."""

from __future__ import annotations

import math
from types import MappingProxyType

from asset_agent.autopilot.state import UavState
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
