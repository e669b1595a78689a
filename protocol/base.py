"""Base model and limits shared by every wire message of protocol version 1."""

from __future__ import annotations

import math
from collections.abc import Iterator
from typing import Annotated, Any

from pydantic import AfterValidator, BaseModel, ConfigDict

PROTOCOL_VERSION = 1
MAX_MESSAGE_BYTES = 1024 * 1024
# Integers a JavaScript client reads exactly (Number.MAX_SAFE_INTEGER); also inside BIGINT columns.
MAX_SAFE_INT = 2**53 - 1
# Timestamps are unix milliseconds in [0, 2100-01-01T00:00:00Z): every store and client can hold them.
MAX_UNIX_MS = 4_102_444_800_000


class Frozen(BaseModel):
    """Immutable pydantic model that rejects unknown fields and non-finite numbers (NaN, inf)."""

    model_config = ConfigDict(frozen=True, extra="forbid", allow_inf_nan=False)


Path = tuple[str | int, ...]


def non_finite(value: Any, path: Path = ()) -> Iterator[Path]:
    """The paths of every NaN or infinite float inside a JSON-like value (dicts, lists, tuples)."""
    stack: list[tuple[Path, Any]] = [(path, value)]
    while stack:
        where, item = stack.pop()
        if isinstance(item, float) and not math.isfinite(item):
            yield where
        elif isinstance(item, dict):
            stack.extend(((*where, k), v) for k, v in reversed(item.items()))
        elif isinstance(item, list | tuple):
            stack.extend(((*where, i), v) for i, v in reversed(list(enumerate(item))))


def dotted(path: Path) -> str:
    """A path as `a.b.0.c`."""
    return ".".join(str(p) for p in path)


def _finite_object(value: dict[str, Any]) -> dict[str, Any]:
    for path in non_finite(value):
        raise ValueError(f"{dotted(path)}: non-finite number (JSON has no NaN or Infinity)")
    return value


# A free-form JSON object (event data, command params and results): any JSON, but only finite numbers.
JsonObject = Annotated[dict[str, Any], AfterValidator(_finite_object)]
