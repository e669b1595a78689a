"""The order `make test` hands files to its workers in (tests/schedule.py)."""

from __future__ import annotations

import json
from types import SimpleNamespace

from tests.schedule import DURATIONS, UNKNOWN_S, longest_first


def items(*nodeids: str) -> list[SimpleNamespace]:
    return [SimpleNamespace(nodeid=n) for n in nodeids]


def test_files_go_longest_first_each_in_its_own_order():
    got = longest_first(
        items("a.py::t1", "b.py::t1", "a.py::t2", "c.py::t[1]", "b.py::t2", "c.py::t[2]"),
        {"a.py": 3.0, "b.py": 300.0, "c.py": 30.0},
    )
    assert [i.nodeid for i in got] == [
        "b.py::t1", "b.py::t2", "c.py::t[1]", "c.py::t[2]", "a.py::t1", "a.py::t2",
    ]  # fmt: skip


def test_a_file_not_recorded_counts_as_a_median_one():
    got = longest_first(
        items("new.py::t", "long.py::t", "short.py::t"), {"long.py": 60.0, "short.py": 1.0}
    )
    assert [i.nodeid for i in got] == ["long.py::t", "new.py::t", "short.py::t"]
    assert 1.0 < UNKNOWN_S < 60.0


def test_the_recorded_durations_are_seconds_per_test_file():
    seconds = json.loads(DURATIONS.read_text())["seconds"]
    assert seconds and all(f.startswith("tests/") and f.endswith(".py") for f in seconds)
    assert all(isinstance(s, float | int) and s >= 0 for s in seconds.values())
