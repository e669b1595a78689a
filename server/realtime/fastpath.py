"""The server's hot path of `protocol.codec.decode` for the one message that arrives thousands of
times a second: UAV telemetry from an asset, checked by a msgspec mirror of its pydantic models
(several times faster) and returned as plain JSON data.

The mirror is at least as strict as the models (`protocol.messages.Telemetry` with
`protocol.telemetry_payloads.UavTelemetry`, strict mode): the same ranges, literals, forbidden
extra keys and finite numbers, and every envelope field required. Anything it does not accept
(invalid, or merely unusual: a landing base's telemetry, a missing `seq`, NaN) returns None and
goes through `protocol.codec.decode`, which gives the usual errors; a test checks the mirror never
accepts what the models refuse.
"""

from __future__ import annotations

import json
import random
import time
import uuid
from typing import Annotated, Any, Literal, NamedTuple

import msgspec
import orjson

from protocol.base import MAX_MESSAGE_BYTES, MAX_SAFE_INT, MAX_UNIX_MS
from protocol.messages import Envelope

_MAX = 1.7976931348623157e308  # the largest finite float: NaN and infinities fail the range
Finite = Annotated[float, msgspec.Meta(ge=-_MAX, le=_MAX)]
Pct = Annotated[float, msgspec.Meta(ge=0, le=100)]
Deg360 = Annotated[float, msgspec.Meta(ge=0, le=360)]
NonNegative = Annotated[float, msgspec.Meta(ge=0, le=_MAX)]


class _S(msgspec.Struct, forbid_unknown_fields=True):
    pass


class _Position(_S):
    lat: Annotated[float, msgspec.Meta(ge=-90, le=90)]
    lon: Annotated[float, msgspec.Meta(ge=-180, le=180)]
    alt_msl_m: Finite
    alt_rel_m: Finite


class _Velocity(_S):
    north_m_s: Finite
    east_m_s: Finite
    down_m_s: Finite


class _Attitude(_S):
    roll_deg: Finite
    pitch_deg: Finite
    yaw_deg: Finite


class _Battery(_S):
    percent: Pct | None = None
    voltage_v: Finite | None = None
    current_a: Finite | None = None


class _Gnss(_S):
    fix: Literal["none", "2d", "3d", "dgps", "rtk_float", "rtk_fixed"]
    satellites: Annotated[int, msgspec.Meta(ge=0, le=255)] | None = None
    hdop: NonNegative | None = None


class _Mission(_S):
    current: Annotated[int, msgspec.Meta(ge=0, le=65535)]
    total: Annotated[int, msgspec.Meta(ge=0, le=65535)]


class _UavTelemetry(_S):
    kind: Literal["uav"]  # the union's tag: required by the models too
    asset_id: uuid.UUID | None = None
    position: _Position | None = None
    velocity: _Velocity | None = None
    heading_deg: Deg360 | None = None
    attitude: _Attitude | None = None
    battery: _Battery | None = None
    gnss: _Gnss | None = None
    flight_mode: str | None = None
    armed: bool = False
    landed_state: Literal["unknown", "on_ground", "in_air", "takeoff", "landing"] = "unknown"
    mission: _Mission | None = None


class _TelemetryEnvelope(_S, omit_defaults=True):  # an empty `re` left out, as the models do
    v: Literal[1]
    id: uuid.UUID
    seq: Annotated[int, msgspec.Meta(ge=0, le=MAX_SAFE_INT)]
    ts: Annotated[int, msgspec.Meta(ge=0, lt=MAX_UNIX_MS)]
    type: Literal["telemetry"]
    payload: _UavTelemetry
    re: uuid.UUID | None = None


_DECODER = msgspec.json.Decoder(_TelemetryEnvelope)
_ENCODER = msgspec.json.Encoder()


class FastTelemetry(NamedTuple):
    """A valid UAV telemetry message, decoded once and encoded for its two destinations."""

    seq: int
    ts: int
    text: bytes  # the envelope as operators receive it (payload.asset_id set), UTF-8 JSON
    payload_json: str  # the payload as stored


def uav_telemetry(text: str | bytes, asset_id: uuid.UUID) -> FastTelemetry | None:
    """`text` as operators and storage take it when it is a valid UAV telemetry message from
    asset `asset_id` (as `decode(text, "asset_to_server")` would accept it), None for anything
    else or anything unsure.

    The mirror is decoded once, its `payload.asset_id` set, the payload encoded by msgspec and
    the envelope written around it: no dict is built and no JSON parsed again. What is encoded is what
    the models would dump: ids in their canonical form, every payload field present (defaults
    filled in), no empty `re`."""
    if len(text) > MAX_MESSAGE_BYTES // 4:
        return None
    try:
        message = _DECODER.decode(text)
    except msgspec.DecodeError:
        return None
    message.payload.asset_id = asset_id
    try:
        payload = _ENCODER.encode(message.payload)
    except (msgspec.EncodeError, UnicodeEncodeError):  # a lone surrogate in a string
        return None
    # the envelope around the encoded payload, in the mirror's field order (what encoding the
    # whole mirror gives, without encoding the payload a second time)
    re = b',"re":"%s"' % str(message.re).encode() if message.re is not None else b""
    envelope = b'{"v":1,"id":"%s","seq":%d,"ts":%d,"type":"telemetry","payload":%s%s}' % (
        str(message.id).encode(),
        message.seq,
        message.ts,
        payload,
        re,
    )
    return FastTelemetry(message.seq, message.ts, envelope, payload.decode())


def operator_text(
    raw: str, msg: Envelope, salvaged: bool, asset_id: str
) -> tuple[str, dict[str, Any]]:
    """A durable message that took the models' path as operators receive it (with `asset_id`),
    and the payload to store.

    Telemetry as received is valid (the model accepted it, extra keys are refused) and is
    re-emitted from its parsed JSON with `asset_id` set; anything else (events, command results,
    a message without its non-finite numbers) is dumped from the model.
    """
    if msg.type == "telemetry" and not salvaged:
        try:
            data = orjson.loads(raw)
            data["payload"]["asset_id"] = asset_id
            return orjson.dumps(data).decode(), data["payload"]
        except (orjson.JSONDecodeError, orjson.JSONEncodeError):
            pass  # an integer past 64 bits: orjson refuses it, pydantic did not
    data = msg.model_dump(mode="json")
    data["payload"]["asset_id"] = asset_id
    return json.dumps(data, separators=(",", ":")), data["payload"]


_IDS = random.Random()  # seeded from the OS once: ids unique, not secret
_VERSION_4 = (0x4000 << 64) | (0x8000 << 48)
_VERSION_MASK = ~((0xF000 << 64) | (0xC000 << 48))


def message_id() -> str:
    """A random (version 4) UUID for a message id, without `uuid.uuid4`'s system call per id:
    acks go out hundreds of times a second, and an envelope id need only be unique."""
    h = f"{(_IDS.getrandbits(128) & _VERSION_MASK) | _VERSION_4:032x}"
    return f"{h[:8]}-{h[8:12]}-{h[12:16]}-{h[16:20]}-{h[20:]}"


def ack_text(seq: int) -> str:
    """An `ack` envelope (what `encode(envelope(AckPayload(seq=seq)))` gives, formatted directly)."""
    return (
        f'{{"v":1,"id":"{message_id()}","seq":0,"ts":{int(time.time() * 1000)},'
        f'"type":"ack","payload":{{"seq":{seq}}}}}'
    )
