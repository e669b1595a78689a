"""Envelope and payload models of every message kind, and one union per direction.

Every WebSocket text message is one envelope:
``{"v": 1, "type": kind, "id": uuid, "seq": int, "ts": unix ms, "re": id?, "payload": {...}}``.

`seq` numbers a sender's durable stream (telemetry, event, command_result from an asset):
it starts at 1, is strictly increasing and is acked by the receiver. Messages outside the
durable stream (hello, rtcm, error, and everything a server or operator sends unless it
numbers them itself) carry ``seq`` 0 and are never acked.
"""

from __future__ import annotations

import base64
import binascii
import time
import uuid
from typing import Annotated, Any, Literal

from pydantic import Field, TypeAdapter, field_validator, model_serializer

from protocol import rtcm
from protocol.base import MAX_SAFE_INT, MAX_UNIX_MS, Frozen, JsonObject
from protocol.telemetry_payloads import LandingBaseTelemetry, TelemetryPayload, UavTelemetry
from protocol.vocabulary import FINAL_STATUSES, CommandStatus, RunProgressPayload

AgentKind = Literal["base_station", "asset_agent", "operator"]
Severity = Literal["info", "warning", "critical"]
Seq = Annotated[int, Field(ge=0, le=MAX_SAFE_INT)]
UnixMs = Annotated[int, Field(ge=0, lt=MAX_UNIX_MS)]  # [1970-01-01, 2100-01-01)
Name = Annotated[str, Field(min_length=1, max_length=200)]


def now_ms() -> int:
    """The current wall-clock time in unix milliseconds."""
    return time.time_ns() // 1_000_000


# --- payloads ---------------------------------------------------------------------------


class HelloPayload(Frozen):
    """Client -> server at session start: who speaks and on which durable stream."""

    stream: uuid.UUID
    agent: AgentKind
    version: Annotated[str, Field(max_length=100)]


class WelcomePayload(Frozen):
    """Server -> client answer to hello: the session and the stream's last stored seq."""

    session_id: Annotated[str, Field(min_length=1, max_length=200)]
    last_acked_seq: Seq
    heartbeat_s: Annotated[float, Field(gt=0)]
    server_time: UnixMs


class EventPayload(Frozen):
    """Something that happened, for people and for the record."""

    asset_id: uuid.UUID | None = None
    name: Name
    severity: Severity = "info"
    message: str = ""
    data: JsonObject = Field(default_factory=dict)


class CommandPayload(Frozen):
    """Server -> asset: run the named command with params before the deadline.

    `params` stays a JSON object here: the receiver parses `(name, params)` into the typed
    command with `protocol.vocabulary.parse`, so a bad one is answered `rejected`, not dropped.
    """

    name: Name
    params: JsonObject = Field(default_factory=dict)
    deadline: UnixMs


class CommandProgress(Frozen):
    """Where a long command is: step name, its index out of total, and a human message."""

    step: str
    index: Annotated[int, Field(ge=0, le=MAX_SAFE_INT)]
    total: Annotated[int, Field(ge=0, le=MAX_SAFE_INT)]
    message: str = ""


class CommandResultPayload(Frozen):
    """Asset -> server result of a command (envelope `re` = the command id)."""

    asset_id: uuid.UUID | None = None
    status: CommandStatus
    reason: str = ""
    progress: CommandProgress | None = None
    data: JsonObject | None = None

    @property
    def final(self) -> bool:
        """True when this result ends the command."""
        return self.status in FINAL_STATUSES


class AckPayload(Frozen):
    """Receiver -> sender: every seq up to this one is stored durably."""

    seq: Seq


class RtcmPayload(Frozen):
    """One RTCM3 frame (CRC-checked), base64-encoded."""

    data: Annotated[str, Field(max_length=2048)]

    @field_validator("data")
    @classmethod
    def _one_frame(cls, value: str) -> str:
        try:
            frame = base64.b64decode(value, validate=True)
        except (binascii.Error, ValueError) as err:
            raise ValueError("data is not valid base64") from err
        if not rtcm.frame_ok(frame):
            raise ValueError("data is not one complete RTCM3 frame with a valid CRC")
        return value

    @classmethod
    def from_frame(cls, frame: bytes) -> RtcmPayload:
        """Wrap one RTCM3 frame."""
        return cls(data=base64.b64encode(frame).decode("ascii"))

    @property
    def frame(self) -> bytes:
        """The RTCM3 frame's bytes."""
        return base64.b64decode(self.data)


class ErrorPayload(Frozen):
    """Either side: a message was refused; `re_seq` names it when its seq was readable."""

    code: Name
    message: str = ""
    re_seq: Seq | None = None


class VideoStatePayload(Frozen):
    """Server -> operator: an asset's live video started or stopped (`GET .../video`'s `state`)."""

    asset_id: uuid.UUID
    state: Literal["live", "offline"]


MAX_IDS_PER_MESSAGE = 5000
AssetIds = Annotated[tuple[uuid.UUID, ...], Field(max_length=MAX_IDS_PER_MESSAGE)]


class SubscribePayload(Frozen):
    """Operator -> server: start receiving these assets' telemetry, events and results."""

    asset_ids: AssetIds


class UnsubscribePayload(Frozen):
    """Operator -> server: stop receiving these assets."""

    asset_ids: AssetIds


# --- envelopes --------------------------------------------------------------------------


class _Envelope(Frozen):
    """Fields every message carries; `re` is left out of the JSON when absent."""

    v: Literal[1] = 1
    id: uuid.UUID = Field(default_factory=uuid.uuid4)
    seq: Seq = 0
    ts: UnixMs = Field(default_factory=now_ms)
    re: uuid.UUID | None = None

    @model_serializer(mode="wrap")
    def _omit_empty_re(self, handler: Any) -> dict[str, Any]:
        data = handler(self)
        if data.get("re") is None:
            data.pop("re", None)
        return data


class Hello(_Envelope):
    """Envelope of kind `hello`."""

    type: Literal["hello"] = "hello"
    payload: HelloPayload


class Welcome(_Envelope):
    """Envelope of kind `welcome`."""

    type: Literal["welcome"] = "welcome"
    payload: WelcomePayload


class Telemetry(_Envelope):
    """Envelope of kind `telemetry`."""

    type: Literal["telemetry"] = "telemetry"
    payload: TelemetryPayload


class Event(_Envelope):
    """Envelope of kind `event`."""

    type: Literal["event"] = "event"
    payload: EventPayload


class Command(_Envelope):
    """Envelope of kind `command`; its `id` is the command id."""

    type: Literal["command"] = "command"
    payload: CommandPayload


class CommandResult(_Envelope):
    """Envelope of kind `command_result`; `re` is the command id."""

    type: Literal["command_result"] = "command_result"
    payload: CommandResultPayload


class Ack(_Envelope):
    """Envelope of kind `ack`."""

    type: Literal["ack"] = "ack"
    payload: AckPayload


class Rtcm(_Envelope):
    """Envelope of kind `rtcm`."""

    type: Literal["rtcm"] = "rtcm"
    payload: RtcmPayload


class Error(_Envelope):
    """Envelope of kind `error`."""

    type: Literal["error"] = "error"
    payload: ErrorPayload


class Subscribe(_Envelope):
    """Envelope of kind `subscribe`."""

    type: Literal["subscribe"] = "subscribe"
    payload: SubscribePayload


class Unsubscribe(_Envelope):
    """Envelope of kind `unsubscribe`."""

    type: Literal["unsubscribe"] = "unsubscribe"
    payload: UnsubscribePayload


class RunProgress(_Envelope):
    """Envelope of kind `run_progress` (server -> operator)."""

    type: Literal["run_progress"] = "run_progress"
    payload: RunProgressPayload


class VideoState(_Envelope):
    """Envelope of kind `video_state` (server -> operator)."""

    type: Literal["video_state"] = "video_state"
    payload: VideoStatePayload


AssetToServer = Annotated[
    Hello | Telemetry | Event | CommandResult | Rtcm | Error, Field(discriminator="type")
]
ServerToAsset = Annotated[Welcome | Command | Ack | Rtcm | Error, Field(discriminator="type")]
OperatorToServer = Annotated[Hello | Subscribe | Unsubscribe | Error, Field(discriminator="type")]
ServerToOperator = Annotated[
    Welcome | Telemetry | Event | CommandResult | RunProgress | VideoState | Error,
    Field(discriminator="type"),
]
AnyMessage = Annotated[
    Hello
    | Welcome
    | Telemetry
    | Event
    | Command
    | CommandResult
    | Ack
    | Rtcm
    | Error
    | Subscribe
    | Unsubscribe
    | RunProgress
    | VideoState,
    Field(discriminator="type"),
]
Envelope = (
    Hello
    | Welcome
    | Telemetry
    | Event
    | Command
    | CommandResult
    | Ack
    | Rtcm
    | Error
    | Subscribe
    | Unsubscribe
    | RunProgress
    | VideoState
)

DIRECTIONS: dict[str, Any] = {
    "asset_to_server": AssetToServer,
    "server_to_asset": ServerToAsset,
    "operator_to_server": OperatorToServer,
    "server_to_operator": ServerToOperator,
    "any": AnyMessage,
}
ADAPTERS: dict[str, TypeAdapter[Any]] = {name: TypeAdapter(tp) for name, tp in DIRECTIONS.items()}
KINDS: dict[str, frozenset[str]] = {
    name: frozenset(
        cls.model_fields["type"].default
        for cls in tp.__origin__.__args__  # type: ignore[attr-defined]
    )
    for name, tp in DIRECTIONS.items()
}

_BY_PAYLOAD: dict[type, type[_Envelope]] = {
    HelloPayload: Hello,
    WelcomePayload: Welcome,
    UavTelemetry: Telemetry,
    LandingBaseTelemetry: Telemetry,
    EventPayload: Event,
    CommandPayload: Command,
    CommandResultPayload: CommandResult,
    AckPayload: Ack,
    RtcmPayload: Rtcm,
    ErrorPayload: Error,
    SubscribePayload: Subscribe,
    UnsubscribePayload: Unsubscribe,
    RunProgressPayload: RunProgress,
    VideoStatePayload: VideoState,
}


def envelope(
    payload: Frozen,
    *,
    seq: int = 0,
    re: uuid.UUID | str | None = None,
    id: uuid.UUID | str | None = None,
    ts: int | None = None,
) -> Envelope:
    """Wrap a payload model in the envelope of its kind (fresh id and timestamp by default)."""
    cls = _BY_PAYLOAD.get(type(payload))
    if cls is None:
        raise TypeError(f"no message kind carries a {type(payload).__name__}")
    fields: dict[str, Any] = {"seq": seq, "re": re, "payload": payload}
    if id is not None:
        fields["id"] = id
    if ts is not None:
        fields["ts"] = ts
    return cls.model_validate(fields)  # type: ignore[return-value]
