"""The hook that runs marked tests at their marker's priority (tests/priority.py): as root (CI)
at that priority, otherwise at their own (only root may raise a priority again)."""

from __future__ import annotations

import os
import threading

import pytest

from tests.conftest import IN_CI
from tests.priority import CPU_BOUND_NICE, REALTIME_NICE, pytest_runtest_call


class Item:
    """As much of a pytest item as the hook reads."""

    def __init__(self, *markers: str) -> None:
        self.markers = markers

    def get_closest_marker(self, name: str) -> object | None:
        return name if name in self.markers else None


def as_root(nice: int, own: int) -> int:
    """The priority a marked call runs at: `nice` as root, its `own` elsewhere; CI runs as root,
    so there a call left at its own is a failure."""
    if os.geteuid() == 0:
        return nice
    if IN_CI:
        pytest.fail("not root: the hook leaves the priority alone (CI runs as root)")
    return own


def nice_of(tid: int) -> int:
    return os.getpriority(os.PRIO_PROCESS, tid)


COLLECTED_AT = nice_of(0)  # this thread's priority when the file was collected, before any call


@pytest.mark.parametrize(
    ("marker", "nice"), [("cpu_bound", CPU_BOUND_NICE), ("realtime", REALTIME_NICE)]
)
def test_a_marked_call_runs_every_thread_at_its_priority_and_then_at_its_own(marker, nice):
    own = nice_of(0)
    ready, done = threading.Event(), threading.Event()
    tids: list[int] = []

    def other() -> None:  # another thread of the worker, a live server's say
        tids.append(threading.get_native_id())
        ready.set()
        done.wait(10)

    thread = threading.Thread(target=other)
    thread.start()
    ready.wait(10)
    try:
        call = pytest_runtest_call(Item(marker))  # type: ignore[arg-type]
        next(call)
        assert nice_of(0) == nice_of(tids[0]) == as_root(nice, own)
        with pytest.raises(StopIteration):
            next(call)
        assert nice_of(0) == nice_of(tids[0]) == own
    finally:
        done.set()
        thread.join(10)


def test_any_other_call_keeps_its_priority():
    own = nice_of(0)
    call = pytest_runtest_call(Item("slow"))  # type: ignore[arg-type]
    next(call)
    assert nice_of(0) == own
    with pytest.raises(StopIteration):
        next(call)


@pytest.mark.cpu_bound
def test_the_hook_is_installed_in_this_session():
    """Marked `cpu_bound`: this very call runs at the lowest priority."""
    assert nice_of(0) == as_root(CPU_BOUND_NICE, COLLECTED_AT)


@pytest.mark.realtime
def test_a_realtime_call_runs_ahead_of_the_others_in_this_session():
    """Marked `realtime`: this very call runs above the default priority."""
    assert nice_of(0) == as_root(REALTIME_NICE, COLLECTED_AT)
