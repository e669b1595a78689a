"""Reading an uploaded mission file: off the event loop, one file at a time per process, and
refused as soon as it holds more items than a mission may have.

A 5 MiB file can hold over 100,000 items; building each before counting them held the event loop
for seconds (issue 48). Here a QGroundControl plan's items are counted while the JSON is parsed
(every object with a `command` key is an item, wherever it stands: a SimpleItem or the flattened
items of a ComplexItem), the parse stops at the first item over the limit, and the parser's hook
being Python, the parse lets the event loop's thread in every switch interval. A waypoint file's
lines are counted before any is read. The parse runs on one thread of its own, so imports
arriving together queue there rather than on the loop.
"""

from __future__ import annotations

import asyncio
import json
from concurrent.futures import ThreadPoolExecutor
from typing import Any

from server.kit.errors import UnsupportedMediaType
from server.missions import qgc, wpl
from server.missions.validate import Problem

JSON_TYPES = {"application/json"}
WPL_TYPES = {"text/plain", wpl.MEDIA_TYPE}

_READER = ThreadPoolExecutor(max_workers=1, thread_name_prefix="mission-import")


class _TooMany(Exception):
    """Raised inside the JSON parser's hook to stop it."""


def plan_document(body: bytes, max_items: int) -> Any:
    """The JSON of a .plan upload; ImportRejected when it is no JSON or holds over `max_items`
    items (found while parsing: the parse stops there)."""
    count = 0

    def pairs(found: list[tuple[str, Any]]) -> dict[str, Any]:
        nonlocal count
        obj = dict(found)
        if "command" in obj:
            count += 1
            if count > max_items:
                raise _TooMany
        return obj

    try:
        return json.loads(body, object_pairs_hook=pairs)
    except _TooMany:
        over = Problem("mission.items", "too many items", f"more than {max_items}", max_items)
        raise qgc.ImportRejected([over]) from None
    except (ValueError, RecursionError) as err:
        raise qgc.ImportRejected([Problem("body", f"not valid JSON: {str(err)[:200]}")]) from err


def read_file(body: bytes, media: str, max_items: int) -> tuple[qgc.Imported, str]:
    """Parse an uploaded file of a known media type; raises ImportRejected."""
    if media in WPL_TYPES:
        try:
            text = body.decode("utf-8-sig")
        except UnicodeDecodeError as err:
            raise qgc.ImportRejected(
                [Problem("body", "a waypoint file must be UTF-8 text")]
            ) from err
        return wpl.parse_wpl(text, max_items=max_items), "wpl"
    return qgc.parse_plan(plan_document(body, max_items)), "qgc"


async def read_import(body: bytes, content_type: str, max_items: int) -> tuple[qgc.Imported, str]:
    """Parse an uploaded file by its content type on the import thread; raises ImportRejected,
    or UnsupportedMediaType (at once) for a type that is neither."""
    media = content_type.split(";")[0].strip().lower()
    if not (media in JSON_TYPES or media.endswith("+json") or media in WPL_TYPES):
        raise UnsupportedMediaType(
            f"content type {media or 'none'!r}: send application/json (QGroundControl .plan) or "
            f"text/plain / {wpl.MEDIA_TYPE} (QGC WPL 110)"
        )
    loop = asyncio.get_running_loop()
    return await loop.run_in_executor(_READER, read_file, body, media, max_items)
