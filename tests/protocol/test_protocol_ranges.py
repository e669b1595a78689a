"""Ranges and finiteness at the edge (issue 14, items 2 and 10): what storage and clients can hold."""

from __future__ import annotations

import json
import math
import uuid

import pytest

from protocol import messages as m
from protocol import telemetry_payloads as t
from protocol.base import MAX_SAFE_INT, MAX_UNIX_MS
from protocol.codec import DecodeError, decode, drop_non_finite, encode


def text(kind: str, payload: object, seq: int = 1, ts: int = 1_767_225_600_000) -> str:
    return json.dumps(
        {"v": 1, "type": kind, "id": str(uuid.uuid4()), "seq": seq, "ts": ts, "payload": payload}
    )


@pytest.mark.parametrize(
    ("seq", "ts", "ok"),
    [
        (MAX_SAFE_INT, 0, True),
        (MAX_SAFE_INT + 1, 0, False),
        (2**63, 0, False),
        (1, MAX_UNIX_MS - 1, True),
        (1, MAX_UNIX_MS, False),
        (1, 10**17, False),
        (1, -1, False),
    ],
)
def test_seq_and_ts_are_bounded(seq: int, ts: int, ok: bool) -> None:
    msg = decode(text("event", {"name": "x"}, seq, ts), "asset_to_server")
    assert isinstance(msg, m.Event) is ok, msg
    if not ok:
        assert isinstance(msg, DecodeError) and msg.code == "invalid_envelope"
        # the error can always be answered: re_seq only names a seq that is in range
        assert m.envelope(msg.to_payload()).payload.re_seq in (None, seq)


@pytest.mark.parametrize("bad", ["NaN", "Infinity", "-Infinity", "1e400"])
@pytest.mark.parametrize(
    ("kind", "payload"),
    [
        ("telemetry", '{"kind": "uav", "heading_deg": %s}'),
        (
            "telemetry",
            '{"kind": "uav", "attitude": {"roll_deg": %s, "pitch_deg": 0, "yaw_deg": 0}}',
        ),
        ("telemetry", '{"kind": "landing_base", "weather": {"temperature_c": %s}}'),
        ("event", '{"name": "x", "data": {"a": [1, {"b": %s}]}}'),
        ("command_result", '{"status": "succeeded", "data": {"v": %s}}'),
    ],
)
def test_non_finite_numbers_are_refused_and_can_be_dropped(
    kind: str, payload: str, bad: str
) -> None:
    raw = text(kind, {}).replace('"payload": {}', '"payload": ' + payload % bad)
    err = decode(raw, "asset_to_server")
    assert isinstance(err, DecodeError) and err.code == "invalid_payload", err
    kept = drop_non_finite(raw, "asset_to_server")
    assert kept is not None and kept.message.type == kind and len(kept.dropped) == 1
    again = encode(kept.message)
    assert "NaN" not in again and "Infinity" not in again and decode(again) == kept.message


def test_a_required_non_finite_field_clears_its_object_and_keeps_the_rest() -> None:
    raw = text(
        "telemetry",
        {"kind": "uav", "armed": True, "position": {"lat": 41.0, "lon": -8.6, "alt_msl_m": 1.0,
         "alt_rel_m": 1.0}, "attitude": {"roll_deg": math.nan, "pitch_deg": 0, "yaw_deg": 0},
         "battery": {"percent": 50, "voltage_v": math.inf}},
    )  # fmt: skip
    kept = drop_non_finite(raw, "asset_to_server")
    assert kept is not None
    assert kept.dropped == ("attitude.roll_deg", "battery.voltage_v")
    assert kept.cleared == ("attitude",)
    payload = kept.message.payload
    assert isinstance(payload, t.UavTelemetry)
    assert payload.attitude is None and payload.armed and payload.position is not None
    assert payload.battery == t.Battery(percent=50)


def test_nothing_is_kept_when_something_else_is_wrong_too() -> None:
    assert (
        drop_non_finite(text("telemetry", {"kind": "uav", "armed": "yes", "heading_deg": math.nan}))
        is None
    )
    assert drop_non_finite(text("telemetry", {"kind": "uav"})) is None  # nothing non-finite
    assert drop_non_finite("{not json") is None
    assert (
        drop_non_finite(text("ack", {"seq": math.nan}), "server_to_asset") is None
    )  # payload root


def test_models_refuse_non_finite_values_when_built() -> None:
    with pytest.raises(ValueError, match="finite"):
        t.Attitude(roll_deg=math.nan, pitch_deg=0, yaw_deg=0)
    with pytest.raises(ValueError, match="non-finite"):
        m.EventPayload(name="x", data={"a": {"b": [math.inf]}})
