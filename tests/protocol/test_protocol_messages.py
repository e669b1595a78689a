"""Golden examples, round trips and bad input for the wire protocol's envelopes."""

from __future__ import annotations

import json
import uuid
from pathlib import Path

import pytest
from hypothesis import given
from hypothesis import strategies as st

from protocol import messages as m
from protocol import rtcm
from protocol import telemetry_payloads as t
from protocol.base import MAX_MESSAGE_BYTES
from protocol.codec import DecodeError, MessageTooLarge, decode, encode, json_schema

GOLDEN = Path(__file__).parent / "golden"

# Which directions carry each golden example.
CARRIERS = {
    "hello": ["asset_to_server", "operator_to_server"],
    "welcome": ["server_to_asset", "server_to_operator"],
    "telemetry_uav": ["asset_to_server", "server_to_operator"],
    "telemetry_landing_base": ["asset_to_server", "server_to_operator"],
    "event": ["asset_to_server", "server_to_operator"],
    "command": ["server_to_asset"],
    "command_result_progress": ["asset_to_server", "server_to_operator"],
    "command_result_final": ["asset_to_server", "server_to_operator"],
    "ack": ["server_to_asset"],
    "rtcm": ["asset_to_server", "server_to_asset"],
    "error": ["asset_to_server", "server_to_asset", "operator_to_server", "server_to_operator"],
    "subscribe": ["operator_to_server"],
    "unsubscribe": ["operator_to_server"],
    "run_progress": ["server_to_operator"],
    "video_state": ["server_to_operator"],
}


def golden(name: str) -> str:
    return (GOLDEN / f"{name}.json").read_text()


def test_every_kind_has_a_golden_example() -> None:
    kinds = {json.loads(golden(name))["type"] for name in CARRIERS}
    assert kinds == set(m.KINDS["any"])
    assert {p.stem for p in GOLDEN.glob("*.json")} == set(CARRIERS)


@pytest.mark.parametrize("name", sorted(CARRIERS))
def test_golden_decodes_and_round_trips(name: str) -> None:
    text = golden(name)
    for direction in [*CARRIERS[name], "any"]:
        msg = decode(text, direction)
        assert not isinstance(msg, DecodeError), msg
        assert json.loads(encode(msg)) == json.loads(text)
        assert decode(encode(msg), direction) == msg


@pytest.mark.parametrize("name", sorted(CARRIERS))
def test_golden_is_refused_in_directions_that_do_not_carry_it(name: str) -> None:
    others = set(m.KINDS) - {"any", *CARRIERS[name]}
    for direction in others:
        err = decode(golden(name), direction)
        assert isinstance(err, DecodeError)
        assert err.code == "unexpected_kind"


def test_decoded_values_are_typed() -> None:
    msg = decode(golden("telemetry_uav"), "asset_to_server")
    assert isinstance(msg, m.Telemetry)
    assert isinstance(msg.payload, t.UavTelemetry)
    assert msg.payload.gnss is not None and msg.payload.gnss.fix == "rtk_fixed"
    assert msg.seq == 42
    base = decode(golden("telemetry_landing_base"))
    assert isinstance(base, m.Telemetry) and isinstance(base.payload, t.LandingBaseTelemetry)
    assert base.payload.faults.names == ("weather_sensor_fault",)
    result = decode(golden("command_result_final"))
    assert isinstance(result, m.CommandResult)
    assert result.re == uuid.UUID("9d3e1a42-7c55-4b8e-8f10-2a6b4c8d0e13")
    assert result.payload.final
    frame = decode(golden("rtcm"))
    assert isinstance(frame, m.Rtcm) and rtcm.frame_ok(frame.payload.frame)


def test_models_are_frozen() -> None:
    msg = decode(golden("ack"))
    assert isinstance(msg, m.Ack)
    with pytest.raises(ValueError):
        msg.seq = 3  # type: ignore[misc]


def test_absent_optional_fields_decode_as_none() -> None:
    text = json.dumps(
        {"v": 1, "type": "telemetry", "id": str(uuid.uuid4()), "seq": 1, "ts": 5,
         "payload": {"kind": "uav", "armed": False}}
    )  # fmt: skip
    msg = decode(text, "asset_to_server")
    assert isinstance(msg, m.Telemetry) and msg.payload.position is None
    assert msg.re is None and '"re"' not in encode(msg)


def _mutate(name: str, change) -> str:
    obj = json.loads(golden(name))
    change(obj)
    return json.dumps(obj)


BAD = {
    "truncated": ('{"v": 1, "type": "ack", ', "malformed_json"),
    "not json": ("hello there", "malformed_json"),
    "invalid utf-8": (b'{"v": 1, "type": "\xff"}', "malformed_json"),
    "array": ("[1, 2]", "invalid_envelope"),
    "no type": (_mutate("ack", lambda o: o.pop("type")), "invalid_envelope"),
    "type not a string": (_mutate("ack", lambda o: o.update(type=5)), "invalid_envelope"),
    "unknown kind": (_mutate("ack", lambda o: o.update(type="launch_missiles")), "unknown_kind"),
    "version 2": (_mutate("ack", lambda o: o.update(v=2)), "unsupported_version"),
    "seq as string": (_mutate("ack", lambda o: o.update(seq="8")), "invalid_envelope"),
    "negative seq": (_mutate("ack", lambda o: o.update(seq=-1)), "invalid_envelope"),
    "id not a uuid": (_mutate("ack", lambda o: o.update(id="nope")), "invalid_envelope"),
    "unknown envelope field": (_mutate("ack", lambda o: o.update(extra=1)), "invalid_envelope"),
    "no payload": (_mutate("ack", lambda o: o.pop("payload")), "invalid_envelope"),
    "ack seq as float": (_mutate("ack", lambda o: o["payload"].update(seq=1.5)), "invalid_payload"),
    "unknown payload field": (
        _mutate("telemetry_uav", lambda o: o["payload"].update(altitude=3)),
        "invalid_payload",
    ),
    "wrong nested type": (
        _mutate("telemetry_uav", lambda o: o["payload"]["position"].update(lat="43.5")),
        "invalid_payload",
    ),
    "latitude out of range": (
        _mutate("telemetry_uav", lambda o: o["payload"]["position"].update(lat=91)),
        "invalid_payload",
    ),
    "unknown asset kind": (
        _mutate("telemetry_uav", lambda o: o["payload"].update(kind="submarine")),
        "invalid_payload",
    ),
    "unknown command status": (
        _mutate("command_result_final", lambda o: o["payload"].update(status="done")),
        "invalid_payload",
    ),
    "rtcm not base64": (
        _mutate("rtcm", lambda o: o["payload"].update(data="%%%")),
        "invalid_payload",
    ),
    "rtcm bad crc": (
        _mutate("rtcm", lambda o: o["payload"].update(data="0wAAAAAA")),
        "invalid_payload",
    ),
    "unknown severity": (
        _mutate("event", lambda o: o["payload"].update(severity="meh")),
        "invalid_payload",
    ),
    "oversize": ('{"v": 1, "pad": "' + "x" * MAX_MESSAGE_BYTES + '"}', "too_large"),
}


@pytest.mark.parametrize("case", sorted(BAD))
def test_bad_input_gives_an_error_value(case: str) -> None:
    text, code = BAD[case]
    err = decode(text, "any")
    assert isinstance(err, DecodeError), err
    assert err.code == code, err
    assert err.message
    assert err.to_payload().code == code


def test_error_names_the_offending_seq_and_field() -> None:
    text = _mutate("telemetry_uav", lambda o: o["payload"].update(armed="yes"))
    err = decode(text, "asset_to_server")
    assert isinstance(err, DecodeError)
    assert err.seq == 42 and err.kind == "telemetry"
    assert "armed" in err.message
    reply = m.envelope(err.to_payload())
    assert isinstance(reply, m.Error) and reply.payload.re_seq == 42


def test_exactly_max_size_is_accepted_one_more_byte_is_not() -> None:
    base = json.loads(golden("event"))
    base["payload"]["message"] = ""
    room = MAX_MESSAGE_BYTES - len(json.dumps(base, separators=(",", ":")))
    base["payload"]["message"] = "é" * (room // 2)  # two bytes each in UTF-8
    text = json.dumps(base, separators=(",", ":"), ensure_ascii=False)
    assert len(text.encode()) <= MAX_MESSAGE_BYTES
    assert isinstance(decode(text), m.Event)
    assert decode(text + " " * (MAX_MESSAGE_BYTES - len(text.encode()) + 1)).code == "too_large"


def test_encode_refuses_oversize() -> None:
    big = m.envelope(m.EventPayload(name="big", data={"blob": "x" * MAX_MESSAGE_BYTES}))
    with pytest.raises(MessageTooLarge):
        encode(big)


def test_envelope_helper_picks_the_kind() -> None:
    cmd_id = uuid.uuid4()
    msg = m.envelope(m.CommandResultPayload(status="rejected", reason="busy"), seq=3, re=cmd_id)
    assert isinstance(msg, m.CommandResult) and msg.re == cmd_id and msg.seq == 3
    assert isinstance(m.envelope(t.LandingBaseTelemetry()), m.Telemetry)
    with pytest.raises(TypeError):
        m.envelope(t.Position(lat=0, lon=0, alt_msl_m=0, alt_rel_m=0))


def test_fault_bits_decode_to_names() -> None:
    faults = t.Faults.from_bits(1 | 16 | 32 | 256)
    assert faults.names == ("panel_motor_stall", "watchdog_expired", "estop", "bit_8")


def test_json_schema_covers_every_kind() -> None:
    schema = json_schema()
    assert set(schema["discriminator"]["mapping"]) == set(m.KINDS["any"])
    asset = json_schema("asset_to_server")
    assert set(asset["discriminator"]["mapping"]) == set(m.KINDS["asset_to_server"])
    json.dumps(schema)


@given(st.binary(max_size=300) | st.text(max_size=300))
def test_decode_never_raises(data: bytes | str) -> None:
    result = decode(data, "any")
    assert isinstance(result, (DecodeError, *m.Envelope.__args__))


@given(
    st.builds(
        t.UavTelemetry,
        heading_deg=st.none() | st.floats(0, 360),
        armed=st.booleans(),
        flight_mode=st.none() | st.text(max_size=20),
        battery=st.none() | st.builds(t.Battery, percent=st.floats(0, 100)),
    ),
    st.integers(min_value=1, max_value=2**53 - 1),
)
def test_uav_telemetry_round_trips(payload: t.UavTelemetry, seq: int) -> None:
    msg = m.envelope(payload, seq=seq)
    assert decode(encode(msg), "asset_to_server") == msg
