"""The longest test files first, so that the parallel run does not end on them.

pytest-xdist's `--dist loadfile` hands out whole files in the order it is given; left to itself it
sorts them by how many tests they hold, which puts the files of one long test (the schema fuzz,
the compose stack, the external-autopilot demos: minutes each) last, and the run's last minutes to
one or two of them while the other workers sit idle. `make test` passes `--no-loadscope-reorder`,
and this orders the files by the seconds they took in a recorded full run (`durations.json`,
longest first; a file not in it counts as `UNKNOWN_S`; `AEROBASE_DURATIONS=path` reads another
file). `make test-durations` records it again:
`AEROBASE_RECORD_DURATIONS=path` makes the run write each file's seconds (setup, call and teardown
of its tests, summed on the controller) there at its end.
"""

from __future__ import annotations

import json
import os
from collections import defaultdict
from pathlib import Path
from typing import Any

import pytest

DURATIONS = Path(__file__).with_name("durations.json")
UNKNOWN_S = 10.0  # a new file, until the next recording: about a median file's time

_recorded: defaultdict[str, float] = defaultdict(float)
_recording = False  # set in the controller (or the only process) when the variable is


def file_of(nodeid: str) -> str:
    """The test file of a node id (tests/x/test_y.py::test_z[param] -> tests/x/test_y.py)."""
    return nodeid.split("::", 1)[0]


def expected_seconds() -> dict[str, float]:
    """Seconds per file from the recorded run (empty when there is none)."""
    path = Path(os.environ.get("AEROBASE_DURATIONS") or DURATIONS)
    try:
        data = json.loads(path.read_text())
    except FileNotFoundError:
        return {}
    return {str(k): float(v) for k, v in data.get("seconds", {}).items()}


def longest_first(items: list[Any], seconds: dict[str, float]) -> list[Any]:
    """The items with their files ordered longest first; a file's own order kept, ties by name."""
    files: dict[str, list[Any]] = {}
    for item in items:
        files.setdefault(file_of(item.nodeid), []).append(item)
    order = sorted(files, key=lambda f: (-seconds.get(f, UNKNOWN_S), f))
    return [item for f in order for item in files[f]]


@pytest.hookimpl(trylast=True)
def pytest_collection_modifyitems(config: pytest.Config, items: list[Any]) -> None:
    items[:] = longest_first(items, expected_seconds())


def pytest_configure(config: pytest.Config) -> None:
    global _recording
    # a worker's reports reach the controller too: counted there, once
    _recording = bool(os.environ.get("AEROBASE_RECORD_DURATIONS")) and not hasattr(
        config, "workerinput"
    )


def pytest_runtest_logreport(report: pytest.TestReport) -> None:
    if _recording:
        _recorded[file_of(report.nodeid)] += report.duration


def pytest_sessionfinish(session: pytest.Session) -> None:
    path = os.environ.get("AEROBASE_RECORD_DURATIONS")
    if not _recording or not path or not _recorded:
        return
    seconds = {f: round(s, 1) for f, s in sorted(_recorded.items())}
    Path(path).write_text(json.dumps({"seconds": seconds}, indent=1) + "\n")
