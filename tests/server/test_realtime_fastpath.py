"""The msgspec mirror of UAV telemetry (server.realtime.fastpath) never accepts what the pydantic models
refuse, and gives the same data for what both accept."""

from __future__ import annotations

import json
import math
import uuid
from typing import Any

from protocol.codec import DecodeError, decode, encode
from protocol.messages import envelope
from protocol.telemetry_payloads import (
    Attitude,
    Battery,
    Gnss,
    MissionProgress,
    Position,
    UavTelemetry,
    Velocity,
)
from server.realtime.fastpath import uav_telemetry

FULL = UavTelemetry(
    position=Position(lat=41.1, lon=-8.6, alt_msl_m=140.2, alt_rel_m=20.0),
    velocity=Velocity(north_m_s=-6.0, east_m_s=6.0, down_m_s=0.05),
    heading_deg=90.0,
    attitude=Attitude(roll_deg=8.5, pitch_deg=-3.2, yaw_deg=90.0),
    battery=Battery(percent=88.0, voltage_v=16.1, current_a=12.3),
    gnss=Gnss(fix="rtk_fixed", satellites=21, hdop=0.6),
    flight_mode="AUTO",
    armed=True,
    landed_state="in_air",
    mission=MissionProgress(current=3, total=12),
)
ODD = [
    None, True, False, 0, -1, 1, 1.0, 0.5, -0.5, 90.0001, 255, 256, 65535, 65536, 2**53, 2**63,
    2**64, -(2**63), 1e308, -1e308, 1e400, "", "x", "uav", "landing_base", "rtk_fixed", [], {},
    {"x": 1}, str(uuid.uuid4()), uuid.uuid4().hex, str(uuid.uuid4()).upper(),
]  # fmt: skip
RAW_ODD = ["NaN", "Infinity", "-Infinity", "1e999", "-0", "1E2", "00", "1.", '"\\ud800"']


def _paths(node: Any, prefix: tuple[str, ...] = ()) -> list[tuple[str, ...]]:
    out = [prefix] if prefix else []
    if isinstance(node, dict):
        for key, value in node.items():
            out += _paths(value, (*prefix, key))
    return out


def _set(root: dict[str, Any], path: tuple[str, ...], value: Any) -> dict[str, Any]:
    copy = json.loads(json.dumps(root))
    node = copy
    for part in path[:-1]:
        node = node[part]
    node[path[-1]] = value
    return copy


def _drop(root: dict[str, Any], path: tuple[str, ...]) -> dict[str, Any]:
    copy = json.loads(json.dumps(root))
    node = copy
    for part in path[:-1]:
        node = node[part]
    del node[path[-1]]
    return copy


def _variants() -> list[str]:
    base = json.loads(encode(envelope(FULL, seq=7)))
    texts = [json.dumps(base)]
    for path in _paths(base):
        for value in ODD:
            texts.append(json.dumps(_set(base, path, value)))
        marker = "__RAW__"
        for raw in RAW_ODD:
            texts.append(json.dumps(_set(base, path, marker)).replace(f'"{marker}"', raw))
        texts.append(json.dumps(_drop(base, path)))
        parent = path[:-1]
        texts.append(json.dumps(_set(base, (*parent, "unexpected"), 1)))
    texts.append(json.dumps(base).replace('"armed": true', '"armed": true, "armed": false'))
    texts += ["[]", "null", "{", json.dumps({**base, "payload": None})]
    return texts


def _flat(node: Any) -> Any:
    """Numbers compared by value (5 and 5.0 are the same JSON number)."""
    if isinstance(node, dict):
        return {k: _flat(v) for k, v in node.items()}
    if isinstance(node, float) and math.isfinite(node) and node == int(node):
        return int(node)
    return node


ASSET = uuid.UUID("6a2f41a0-0000-4000-8000-000000000001")


def fast_data(text: str) -> dict[str, Any] | None:
    """What the fast path gives operators, as data."""
    fast = uav_telemetry(text, ASSET)
    if fast is None:
        return None
    data = json.loads(fast.text)
    assert json.loads(fast.payload_json) == data["payload"]  # stored as sent to operators
    return data  # type: ignore[no-any-return]


def test_the_mirror_accepts_nothing_the_models_refuse() -> None:
    accepted = 0
    for text in _variants():
        fast = fast_data(text)
        if fast is None:
            continue
        accepted += 1
        model = decode(text, "asset_to_server")
        assert not isinstance(model, DecodeError), (
            f"fast path accepted what the model refuses: {text}"
        )
        dumped = model.model_dump(mode="json")
        assert fast["payload"].pop("asset_id") == str(ASSET)  # the socket's asset, set by us
        dumped["payload"].pop("asset_id", None)
        assert _flat(fast) == _flat(dumped), text
    assert accepted > 50  # the mirror is the fast path for valid telemetry, not a no-op


def test_the_mirror_takes_valid_telemetry_and_leaves_the_rest_to_decode() -> None:
    text = encode(envelope(FULL, seq=3))
    data = fast_data(text)
    assert data is not None and data["seq"] == 3 and data["payload"]["gnss"]["fix"] == "rtk_fixed"
    assert "re" not in data  # an empty `re` is left out, as the models leave it
    answer = uuid.uuid4()
    with_re = json.loads(text)
    with_re["re"] = str(answer).upper()  # valid in any case; the canonical form goes out
    replied = fast_data(json.dumps(with_re))
    assert replied is not None and replied["re"] == str(answer)
    sparse = encode(envelope(UavTelemetry(), seq=4))
    assert fast_data(sparse) is not None
    upper = text.replace(json.loads(text)["id"], json.loads(text)["id"].upper())
    assert fast_data(upper)["id"] == json.loads(text)["id"]  # type: ignore[index]
    for other in ('{"v":1}', text.replace('"kind":"uav"', '"kind":"landing_base"'), "x" * 10):
        assert uav_telemetry(other, ASSET) is None


def test_the_preformatted_ack_is_what_the_models_encode() -> None:
    from protocol.messages import Ack, AckPayload
    from server.realtime.fastpath import ack_text

    text = ack_text(2**53 - 1)
    ack = decode(text, "server_to_asset")
    assert isinstance(ack, Ack) and ack.payload.seq == 2**53 - 1
    reference = json.loads(encode(envelope(AckPayload(seq=5))))
    assert list(json.loads(ack_text(5))) == list(reference)
    assert {k: v for k, v in json.loads(ack_text(5)).items() if k not in ("id", "ts")} == {
        k: v for k, v in reference.items() if k not in ("id", "ts")
    }
