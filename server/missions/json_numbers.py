"""Numbers of an uploaded JSON document that are not finite doubles, found before anything reads them.

Python's JSON reader accepts a bare `NaN`, `Infinity` and `-Infinity` (not JSON), reads `1e400` as
Infinity and keeps `10**400` as an integer no float can hold. None of them can be checked, stored
(PostgreSQL's JSON refuses NaN) or sent back as JSON, so an import refuses them, each named by its
path and, inside `mission.items`, by its item.
"""

from __future__ import annotations

import math
import re
from typing import Any

from server.kit.errors import non_finite_token
from server.missions.validate import Problem

PARAM_NAMES = {4: "latitude", 5: "longitude", 6: "altitude"}
MAX_NUMBER_PROBLEMS = 50
_ITEM_PATH = re.compile(r"mission\.items\[(\d+)\]")
_PARAM = re.compile(r"params\[(\d)\]")


def unrepresentable(value: Any) -> str | None:
    """Why a parsed JSON value is a number we cannot keep; None when it is fine (or no number)."""
    if isinstance(value, float) and not math.isfinite(value):
        token = non_finite_token(value)
        return token if token == "NaN" else f"{token}, or beyond the range of a 64-bit float"
    if isinstance(value, int) and not isinstance(value, bool):
        try:
            float(value)
        except OverflowError:
            return f"an integer of {value.bit_length()} bits, beyond the range of a 64-bit float"
    return None


def non_finite_numbers(document: Any) -> list[Problem]:
    """A Problem for every unrepresentable number of `document` (at most MAX_NUMBER_PROBLEMS)."""
    problems: list[Problem] = []
    stack: list[tuple[Any, str]] = [(document, "")]
    while stack and len(problems) < MAX_NUMBER_PROBLEMS:
        value, path = stack.pop()
        if isinstance(value, dict):
            stack += [(v, f"{path}.{k}" if path else str(k)) for k, v in reversed(value.items())]
        elif isinstance(value, list):
            stack += [(v, f"{path}[{n}]") for n, v in reversed(list(enumerate(value)))]
        elif (why := unrepresentable(value)) is not None:
            problems.append(_problem(document, path, why))
    return problems


def _item(document: Any, index: int) -> Any:
    try:
        return document["mission"]["items"][index]
    except (KeyError, IndexError, TypeError):
        return None


def _problem(document: Any, path: str, why: str) -> Problem:
    """`item 3: params[4] (latitude) is not a finite number (NaN)`, or the path outside items."""
    m = _ITEM_PATH.match(path)
    raw = _item(document, int(m.group(1))) if m else None
    if m is None or not isinstance(raw, dict):
        return Problem(path, f"{path} is not a finite number ({why})", why.split(",")[0])
    index = int(m.group(1))
    field = path[m.end() :].lstrip(".") or "the item"
    if (p := _PARAM.fullmatch(field)) and int(p.group(1)) in PARAM_NAMES:
        field = f"{field} ({PARAM_NAMES[int(p.group(1))]})"
    command = raw.get("command")
    return Problem(
        path,
        f"item {index}: {field} is not a finite number ({why})",
        why.split(",")[0],
        index=index,
        command=command if isinstance(command, int) and not isinstance(command, bool) else None,
    )
