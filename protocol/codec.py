"""Encode envelopes to JSON text and decode JSON text to envelopes, errors as values.

`decode` never raises for bad input: it returns a `DecodeError` whose `code` is one of
too_large, malformed_json, invalid_envelope, unsupported_version, unknown_kind,
unexpected_kind (a known kind that this direction does not carry) or invalid_payload.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from typing import Any, Literal

from pydantic import ValidationError

from protocol.base import MAX_MESSAGE_BYTES, PROTOCOL_VERSION
from protocol.messages import ADAPTERS, KINDS, Envelope, ErrorPayload

Direction = Literal[
    "asset_to_server", "server_to_asset", "operator_to_server", "server_to_operator", "any"
]
ErrorCode = Literal[
    "too_large",
    "malformed_json",
    "invalid_envelope",
    "unsupported_version",
    "unknown_kind",
    "unexpected_kind",
    "invalid_payload",
]
_MAX_DETAILS = 3


class MessageTooLarge(ValueError):
    """An outgoing message would exceed MAX_MESSAGE_BYTES."""


@dataclass(frozen=True, slots=True)
class DecodeError:
    """Why a text could not be decoded, with its seq and id when those were readable."""

    code: ErrorCode
    message: str
    seq: int | None = None
    id: str | None = None
    kind: str | None = None

    def to_payload(self) -> ErrorPayload:
        """The `error` payload to answer the sender with."""
        return ErrorPayload(code=self.code, message=self.message, re_seq=self.seq)


def encode(message: Envelope) -> str:
    """Serialise one envelope to its JSON text; raise MessageTooLarge past the limit."""
    text = message.model_dump_json()
    if len(text) > MAX_MESSAGE_BYTES // 4 and len(text.encode()) > MAX_MESSAGE_BYTES:
        raise MessageTooLarge(f"{message.type} message exceeds {MAX_MESSAGE_BYTES} bytes")
    return text


def decode(text: str | bytes, direction: Direction = "any") -> Envelope | DecodeError:
    """Parse and validate one message as carried in `direction`; bad input gives a DecodeError."""
    if _too_large(text):
        return DecodeError("too_large", f"message exceeds {MAX_MESSAGE_BYTES} bytes")
    try:
        return ADAPTERS[direction].validate_json(text, strict=True)
    except ValidationError as err:
        return _classify(text, err, direction)


def json_schema(direction: Direction = "any") -> dict[str, Any]:
    """The JSON Schema of the envelope union of one direction."""
    return ADAPTERS[direction].json_schema(mode="validation")


def _too_large(text: str | bytes) -> bool:
    if len(text) <= MAX_MESSAGE_BYTES // 4:
        return False
    raw = text.encode() if isinstance(text, str) else text
    return len(raw) > MAX_MESSAGE_BYTES


def _peek(text: str | bytes) -> dict[str, Any] | None:
    """The raw JSON object, for reporting only (None when it is not one)."""
    try:
        obj = json.loads(text)
    except (ValueError, UnicodeDecodeError):
        return None
    return obj if isinstance(obj, dict) else None


def _classify(text: str | bytes, err: ValidationError, direction: Direction) -> DecodeError:
    errors = err.errors(include_url=False, include_input=False)
    first = errors[0]
    if first["type"] == "json_invalid":
        return DecodeError("malformed_json", f"malformed JSON: {first['msg']}")
    raw = _peek(text)
    if raw is None:
        return DecodeError("invalid_envelope", "a message must be one JSON object")
    seq = raw.get("seq") if type(raw.get("seq")) is int and raw["seq"] >= 0 else None
    msg_id = raw.get("id") if isinstance(raw.get("id"), str) else None
    kind = raw.get("type") if isinstance(raw.get("type"), str) else None

    def fail(code: ErrorCode, message: str) -> DecodeError:
        return DecodeError(code, message, seq=seq, id=msg_id, kind=kind)

    if "v" in raw and raw["v"] != PROTOCOL_VERSION:
        return fail("unsupported_version", f"protocol version {raw['v']!r} is not supported")
    if first["loc"] == () and first["type"] in ("union_tag_not_found", "union_tag_invalid"):
        if kind is None:
            return fail("invalid_envelope", "missing or non-string 'type'")
        if kind in KINDS["any"]:
            return fail("unexpected_kind", f"kind {kind!r} is not accepted here ({direction})")
        return fail("unknown_kind", f"unknown message kind {kind!r}")
    details = "; ".join(_describe(e) for e in errors[:_MAX_DETAILS])
    if len(errors) > _MAX_DETAILS:
        details += f"; and {len(errors) - _MAX_DETAILS} more"
    in_payload = all(_in_payload(e) for e in errors)
    return fail("invalid_payload" if in_payload else "invalid_envelope", details)


def _in_payload(error: Any) -> bool:
    loc = error["loc"]
    if len(loc) < 2 or loc[1] != "payload":
        return False
    return not (len(loc) == 2 and error["type"] == "missing")


def _describe(error: Any) -> str:
    # loc is (kind, field, ...): drop the kind, which the union put first.
    loc = ".".join(str(part) for part in error["loc"][1:]) or "message"
    return f"{loc}: {error['msg']}"
