"""The telemetry store interface: append batches, read ranges (raw or downsampled), read the latest.

A sample is one telemetry payload of one asset at one time, as the asset sent it (nested); what
readers see is its flat form, dotted field names to numbers, booleans or strings (`flatten`; a
payload stored flat before reads the same). Two implementations: `SqlTelemetryStore` (default,
the main database: the payload as JSON, flattened when read) and `InfluxTelemetryStore`
(INFLUXDB_URL: one field per flat name).
"""

from __future__ import annotations

import uuid
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from datetime import datetime
from typing import TYPE_CHECKING, Any, Literal, Protocol, cast

import orjson

from server.kit.db import json_dumps

if TYPE_CHECKING:
    from sqlalchemy.ext.asyncio import AsyncSession

Scalar = float | int | bool | str
Aggregate = Literal["mean", "last"]


@dataclass(frozen=True)
class Sample:
    """One telemetry sample of one asset."""

    asset_id: uuid.UUID
    ts: datetime  # aware, UTC
    seq: int
    fields: Mapping[str, Any] = field(default_factory=dict)  # nested payload, or already flat
    fields_json: str | None = None  # the same payload as JSON, when it came encoded already

    def data(self) -> Mapping[str, Any]:
        """The payload as data (parsed from `fields_json` when that is what it carries)."""
        if self.fields_json is not None and not self.fields:
            return cast(Mapping[str, Any], orjson.loads(self.fields_json))
        return self.fields

    def json(self) -> str:
        """The payload as JSON text (encoded only when it came as data)."""
        return self.fields_json if self.fields_json is not None else json_dumps(self.fields)


@dataclass(frozen=True)
class Query:
    """A range read: raw samples, or one row per `every_s` bucket aggregated by `agg`."""

    asset_id: uuid.UUID
    start: datetime
    end: datetime
    fields: Sequence[str] | None = None  # None: every field
    every_s: float | None = None
    agg: Aggregate = "mean"  # numeric fields; non-numeric fields always take the last value
    limit: int = 10_000


class TelemetryStore(Protocol):
    """Where telemetry samples live."""

    in_database: bool  # the samples live in the main database (they join its transactions)

    async def start(self) -> None:
        """Connect and prepare (create buckets/retention policies where needed)."""

    async def ping(self) -> None:
        """Return when the store answers; raise when it cannot be reached."""

    async def close(self) -> None:
        """Flush and disconnect."""

    async def write(self, samples: Sequence[Sample], db: AsyncSession | None = None) -> None:
        """Store a batch durably; returns only when it is stored. `db` is the caller's open
        transaction on the main database: a store living there joins it (the caller commits),
        any other store ignores it and is durable on return."""

    async def query(self, q: Query) -> list[dict[str, Any]]:
        """Rows `{"ts": iso8601, field: value, ...}` in time order."""

    async def latest(self, asset_id: uuid.UUID) -> dict[str, Any] | None:
        """The newest sample of an asset as a row, or None."""

    async def prune(self, before: datetime) -> int:
        """Delete samples older than `before` (retention); returns how many, when known."""


_SCALARS = (bool, int, float, str)


def flatten(payload: Mapping[str, Any], prefix: str = "") -> dict[str, Scalar]:
    """Nested telemetry -> flat dotted fields; None values are dropped, lists are skipped."""
    out: dict[str, Scalar] = {}
    _flatten_into(out, payload, prefix)
    return out


def _flatten_into(out: dict[str, Scalar], payload: Mapping[str, Any], prefix: str) -> None:
    # exact type checks first (decoded JSON is plain dicts and scalars): no ABC look-ups per value
    for key, value in payload.items():
        kind = type(value)
        if kind in _SCALARS:
            out[prefix + key if prefix else key] = value
        elif kind is dict or isinstance(value, Mapping):
            _flatten_into(out, value, f"{prefix}{key}.")
        elif isinstance(value, _SCALARS):  # subclasses (an IntEnum, a str enum)
            out[prefix + key if prefix else key] = value


async def retention_loop(store: TelemetryStore, keep_days: float, every_s: float = 3600.0) -> None:
    """Delete samples older than `keep_days`, now and then every `every_s` seconds."""
    import asyncio
    import logging
    from datetime import UTC, timedelta
    from datetime import datetime as _dt

    log = logging.getLogger(__name__)
    while True:
        try:
            removed = await store.prune(_dt.now(UTC) - timedelta(days=keep_days))
            if removed:
                log.info(
                    "telemetry retention removed %d samples older than %.1f days",
                    removed,
                    keep_days,
                )
        except asyncio.CancelledError:
            raise
        except Exception:
            log.exception("telemetry retention failed")
        await asyncio.sleep(every_s)
