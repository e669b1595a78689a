"""MAVLink waypoint files (`QGC WPL 110` text) to and from mission items. Pure functions.

One line per item, tab separated: INDEX CURRENT FRAME COMMAND P1 P2 P3 P4 LAT LON ALT
AUTOCONTINUE. Line 0 is home (AMSL). Every line we cannot take is named, never dropped.
"""

from __future__ import annotations

import math

from server.missions.items import (
    COMMANDS,
    MissionItem,
    command_name,
    frame_problem,
    normalize_frame,
)
from server.missions.qgc import Imported, ImportRejected
from server.missions.validate import Home, Problem

HEADER = "QGC WPL 110"
MEDIA_TYPE = "application/vnd.mavlink.wpl"


def _float(text: str) -> float | None:
    """A field as a finite float, None for nan; ValueError for anything else."""
    value = float(text)
    if math.isnan(value):
        return None
    if not math.isfinite(value):
        raise ValueError(text)
    return value


def parse_wpl(text: str, *, max_items: int | None = None) -> Imported:
    """`QGC WPL 110` text -> Imported; raises ImportRejected naming every line it cannot take,
    or, before reading any, the file when it has more lines than home and `max_items` items."""
    lines = [ln.strip() for ln in text.replace("\r\n", "\n").replace("\r", "\n").split("\n")]
    lines = [ln for ln in lines if ln]
    if max_items is not None and len(lines) - 2 > max_items:  # the header and home are no items
        raise ImportRejected([Problem("lines", "too many items", len(lines) - 2, max_items)])
    if not lines or lines[0].split() != HEADER.split():
        got = lines[0][:40] if lines else ""
        raise ImportRejected(
            [
                Problem(
                    "line 1",
                    f'not a waypoint file (the first line must be "{HEADER}")',
                    got,
                    HEADER,
                )
            ]
        )
    problems: list[Problem] = []
    home: Home | None = None
    items: list[MissionItem] = []
    for n, line in enumerate(lines[1:]):
        where = f"line {n + 2}"
        index = n - 1 if n > 0 else None  # our items exclude home (line 0)
        fields = line.split()
        if len(fields) != 12:
            problems.append(
                Problem(where, "a waypoint line has 12 fields", len(fields), 12, index=index)
            )
            continue
        try:
            seq, _current, frame, command = (int(f) for f in fields[:4])
            numbers = [_float(f) for f in fields[4:11]]
            auto = int(float(fields[11]))
        except (ValueError, OverflowError):
            problems.append(
                Problem(
                    where,
                    "fields must be finite numbers (nan for no value; not inf, not beyond 1.8e308)",
                    line[:120],
                    index=index,
                )
            )
            continue
        if seq != n:
            problems.append(
                Problem(where, "items must be numbered 0, 1, 2, ... in order", seq, n, index=index)
            )
            continue
        if n == 0:
            lat, lon, alt = numbers[4], numbers[5], numbers[6]
            if lat is None or lon is None:
                problems.append(Problem(where, "home needs a latitude and a longitude", None))
            elif (lat, lon) != (0.0, 0.0):  # 0, 0 is how tools write "no home"
                home = Home(lat, lon, alt or 0.0)
            continue
        if command not in COMMANDS:
            problems.append(
                Problem(
                    where,
                    f"unsupported command {command_name(command)}",
                    command,
                    sorted(COMMANDS),
                    index=index,
                    command=command,
                )
            )
            continue
        why = frame_problem(command, frame)
        if why:
            problems.append(Problem(where, why, frame, index=index, command=command))
            continue
        items.append(
            MissionItem(
                command=command,
                frame=normalize_frame(frame),
                params=(numbers[0], numbers[1], numbers[2], numbers[3]),
                lat=numbers[4] or 0.0,
                lon=numbers[5] or 0.0,
                alt=numbers[6] or 0.0,
                autocontinue=bool(auto),
            )
        )
    if problems:
        raise ImportRejected(problems)
    return Imported(items=items, home=home)


def _fmt(value: float | None) -> str:
    if value is None:
        return "nan"
    return repr(float(value))


def export_wpl(items: list[MissionItem], home: Home | None) -> str:
    """Mission items -> `QGC WPL 110` text, home as line 0 (0, 0, 0 when unknown)."""
    h = home or Home(0.0, 0.0, 0.0)
    rows = [
        HEADER,
        "\t".join(
            ["0", "1", "0", "16", "0", "0", "0", "0", _fmt(h.lat), _fmt(h.lon), _fmt(h.alt), "1"]
        ),
    ]
    for n, item in enumerate(items, start=1):
        rows.append(
            "\t".join(
                [
                    str(n),
                    "0",
                    str(item.frame),
                    str(item.command),
                    *(_fmt(p) for p in item.params),
                    _fmt(item.lat),
                    _fmt(item.lon),
                    _fmt(item.alt),
                    "1" if item.autocontinue else "0",
                ]
            )
        )
    return "\n".join(rows) + "\n"
