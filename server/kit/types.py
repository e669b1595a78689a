"""Request field types that every schema shares: bounded text without NUL bytes."""

from __future__ import annotations

import math
import re
from datetime import UTC, datetime
from typing import Annotated, Any

from pydantic import AfterValidator, PlainSerializer, StringConstraints, WithJsonSchema

from server.kit.time import rfc3339


def _no_control(value: str) -> str:
    if "\x00" in value:
        raise ValueError("must not contain NUL characters")
    return value


def _email(value: str) -> str:
    value = value.strip().lower()
    if not re.fullmatch(r"[^@\s]{1,64}@[^@\s]{1,255}", value):
        raise ValueError("not an e-mail address")
    return value


def _name(value: str) -> str:
    if any(ord(c) < 32 for c in value):
        raise ValueError("must not contain control characters")
    return value


def _utc(value: datetime) -> datetime:
    if value.tzinfo is None:
        raise ValueError("needs a time zone offset (RFC 3339), e.g. 2026-11-22T10:00:00Z")
    return value.astimezone(UTC)


# every time of every REST body and query: in, any RFC 3339 offset (normalised to UTC; no offset
# is refused); out, always UTC with `Z`
Timestamp = Annotated[
    datetime,
    AfterValidator(_utc),
    PlainSerializer(rfc3339, when_used="json"),
    WithJsonSchema(
        {
            "type": "string",
            "format": "date-time",
            "description": "RFC 3339; answers are always UTC with Z",
            "examples": ["2026-11-22T05:00:00Z"],
        }
    ),
]

Text = Annotated[str, StringConstraints(max_length=2000), AfterValidator(_no_control)]
Name = Annotated[
    str,
    StringConstraints(min_length=1, max_length=100, strip_whitespace=True),
    AfterValidator(_name),
]
Email = Annotated[str, StringConstraints(min_length=3, max_length=320), AfterValidator(_email)]
Password = Annotated[
    str, StringConstraints(min_length=12, max_length=1024), AfterValidator(_no_control)
]
LoginPassword = Annotated[
    str, StringConstraints(min_length=1, max_length=1024), AfterValidator(_no_control)
]


MAX_JSON_DEPTH = 16


def _json_value(value: Any, path: str = "", depth: int = 0) -> None:
    """Raise ValueError for what JSON columns cannot hold: NaN/Infinity, NUL, absurd nesting."""
    if depth > MAX_JSON_DEPTH:
        raise ValueError(f"{path or 'value'}: nested deeper than {MAX_JSON_DEPTH} levels")
    if isinstance(value, float) and not math.isfinite(value):
        raise ValueError(f"{path or 'value'}: {value!r} is not a finite number (JSON has no NaN)")
    if isinstance(value, str) and "\x00" in value:
        raise ValueError(f"{path or 'value'}: must not contain NUL characters")
    if isinstance(value, dict):
        for k, v in value.items():
            _json_value(str(k), path, depth + 1)
            _json_value(v, f"{path}.{k}" if path else str(k), depth + 1)
    elif isinstance(value, list):
        for n, v in enumerate(value):
            _json_value(v, f"{path}[{n}]", depth + 1)


def _json_object(value: dict[str, Any]) -> dict[str, Any]:
    _json_value(value)
    return value


# free-form JSON kept as it is (asset attributes): finite numbers only, stored and sent back as JSON
JsonObject = Annotated[dict[str, Any], AfterValidator(_json_object)]
