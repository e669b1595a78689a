"""Encode envelopes to JSON text and decode JSON text to envelopes, errors as values.

`decode` never raises for bad input: it returns a `DecodeError` whose `code` is one of
too_large, malformed_json, invalid_envelope, unsupported_version, unknown_kind,
unexpected_kind (a known kind that this direction does not carry) or invalid_payload.
`drop_non_finite` recovers a message whose only fault is NaN or infinite numbers in its payload.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from typing import Any, Literal

from pydantic import ValidationError

from protocol.base import (
    MAX_MESSAGE_BYTES,
    MAX_SAFE_INT,
    PROTOCOL_VERSION,
    Path,
    dotted,
    non_finite,
)
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
_MAX_DEPTH = 16


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


@dataclass(frozen=True, slots=True)
class Salvaged:
    """A message kept without its non-finite numbers; `dropped` names them (`attitude.roll_deg`)
    and `cleared` the payload fields set to null for it (`attitude`, when its `roll_deg` is required).
    """

    message: Envelope
    dropped: tuple[str, ...]
    cleared: tuple[str, ...]


def drop_non_finite(text: str | bytes, direction: Direction = "any") -> Salvaged | None:
    """The message with every NaN/infinite number of its payload dropped, or None when it has none
    or is still invalid without them.

    A dropped number becomes null; when its field may not be null, the closest enclosing object
    that may be is cleared instead (a position without a finite latitude is no position).
    """
    if _too_large(text):
        return None
    try:
        obj = json.loads(text)  # Python's parser reads NaN, Infinity and 1e400 (as inf)
    except (ValueError, RecursionError):
        return None
    payload = obj.get("payload") if isinstance(obj, dict) else None
    if not isinstance(payload, dict):
        return None
    bad = list(non_finite(payload))
    if not bad:
        return None
    for path in bad:
        _put(payload, path, None)
    nulled, cleared = set(bad), []
    for _ in range(_MAX_DEPTH):
        try:
            message = ADAPTERS[direction].validate_json(json.dumps(obj), strict=True)
        except (ValidationError, RecursionError) as err:
            if not isinstance(err, ValidationError):
                return None
            parents = {_parent(p) for p in _error_paths(payload, err) if p in nulled}
            if not parents or () in parents:
                return None
            for parent in parents:
                _put(payload, parent, None)
                nulled.add(parent)
                cleared.append(dotted(parent))
            continue
        return Salvaged(message, tuple(dotted(p) for p in bad), tuple(cleared))
    return None


def _put(root: Any, path: Path, value: Any) -> None:
    for part in path[:-1]:
        root = root[part]
    root[path[-1]] = value


def _parent(path: Path) -> Path:
    return path[:-1]


def _error_paths(payload: dict[str, Any], err: ValidationError) -> set[Path]:
    """Payload paths of the errors: pydantic's locations minus the union tags they include."""
    out = set()
    for error in err.errors(include_url=False, include_input=False):
        loc = error["loc"]
        if len(loc) < 2 or loc[1] != "payload":
            continue
        node: Any = payload
        path: list[str | int] = []
        for part in loc[2:]:
            if isinstance(node, dict) and part in node:
                node = node[part]
            elif isinstance(node, list) and isinstance(part, int) and 0 <= part < len(node):
                node = node[part]
            else:
                continue  # a union tag (`uav`, `landing_base`), not a key of the payload
            path.append(part)
        out.add(tuple(path))
    return out


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
    seq = raw.get("seq")
    seq = seq if type(seq) is int and 0 <= seq <= MAX_SAFE_INT else None
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
