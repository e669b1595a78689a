"""The order `make test` hands files to its workers in (tests/schedule.py)."""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
from pathlib import Path
from types import SimpleNamespace

import pytest

from tests.schedule import DURATIONS, UNKNOWN_S, longest_first

ROOT = Path(__file__).resolve().parents[1]


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


def _worker_order(tmp_path: Path, flags: list[str]) -> list[str]:
    """The files one xdist worker ran, in order: a one-test file recorded long and a three-test
    file recorded short, given short first (so the collection's own order is not the answer)."""
    (tmp_path / "test_many.py").write_text(
        "def test_a(): pass\ndef test_b(): pass\ndef test_c(): pass\n"
    )
    (tmp_path / "test_long.py").write_text("def test_only(): pass\n")
    durations = tmp_path / "durations.json"
    durations.write_text(json.dumps({"seconds": {"test_long.py": 100.0, "test_many.py": 1.0}}))
    env = {**os.environ, "AEROBASE_DURATIONS": str(durations), "PYTHONPATH": str(ROOT)}
    env.pop("AEROBASE_RECORD_DURATIONS", None)
    cmd = [sys.executable, "-m", "pytest", "-p", "tests.schedule", "-p", "no:cacheprovider"]
    cmd += [*flags, "-v", "--rootdir", str(tmp_path), "-c", os.devnull]
    out = subprocess.run(
        [*cmd, "test_many.py", "test_long.py"],
        cwd=tmp_path, env=env, capture_output=True, text=True, timeout=120, check=False,
    )  # fmt: skip
    assert out.returncode == 0, out.stdout + out.stderr
    ran = re.findall(r"PASSED (test_\w+\.py)::", out.stdout)
    assert len(ran) == 4, out.stdout
    return list(dict.fromkeys(ran))


def _make_parallel() -> list[str]:
    """`make test`'s xdist flags, from the Makefile, on one worker."""
    line = re.search(r"^PARALLEL \?=(.*)$", (ROOT / "Makefile").read_text(), re.M)
    assert line, "PARALLEL not in the Makefile"
    flags = line.group(1).split()
    i = flags.index("-n")
    return [*flags[:i], "-n", "1", *flags[i + 2 :]]


@pytest.mark.slow  # two pytest runs with a worker each: 9 s; `make test`'s order only
def test_make_tests_workers_get_the_longest_file_first(tmp_path):
    """The order survives xdist: `make test`'s flags keep its own reordering (by test count) off."""
    assert _worker_order(tmp_path, _make_parallel()) == ["test_long.py", "test_many.py"]


@pytest.mark.slow
def test_xdist_left_to_itself_puts_the_file_of_more_tests_first(tmp_path):
    """What the flag above is for (and what the test above would see without it)."""
    flags = [f for f in _make_parallel() if f != "--no-loadscope-reorder"]
    assert _worker_order(tmp_path, flags) == ["test_many.py", "test_long.py"]
