"""CPU-bound tests run at the lowest CPU priority, so that the real-time ones beside them keep up.

`make test` runs three workers on two cores. Most end-to-end tests fly the simulated world in
real time at a speed factor, against an agent whose detection and LANDING_TARGETs must keep up
with it; a test marked `cpu_bound` (the precision-landing evaluation flown in simulated time, the
schema fuzz) only needs the CPU, whenever it comes. Beside two such tests, on a machine where a
plain 20 M-addition Python loop takes 3.0-3.7 s, the windy LANDING_TARGET landing sent its targets
at 11.4 Hz and took 148 s, 2.7 cm off (in one full run: 7.5 Hz, 7.4 cm, off the 5 cm contacts);
with them at nice 19, 12.9 Hz in 87 s, 1.1 cm, as alone (16.1 Hz, 95 s, 1.6 cm). So while a
`cpu_bound` test runs, every thread of its worker (Linux keeps a nice value per thread: the
test's, a live server's in the same process) and whatever they start is at nice
`CPU_BOUND_NICE`, each back at its own after. Raising a priority again needs root (CAP_SYS_NICE),
which CI has; elsewhere the priority is left alone.
"""

from __future__ import annotations

import contextlib
import os
import threading
from collections.abc import Iterator

import pytest

CPU_BOUND_NICE = 19


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_call(item: pytest.Item) -> Iterator[None]:
    """A `cpu_bound` test's call with its worker's threads at the lowest priority."""
    if item.get_closest_marker("cpu_bound") is None or os.geteuid() != 0:
        yield
        return
    before = {}
    for tid in map(int, os.listdir("/proc/self/task")):
        try:
            before[tid] = os.getpriority(os.PRIO_PROCESS, tid)
            os.setpriority(os.PRIO_PROCESS, tid, CPU_BOUND_NICE)
        except ProcessLookupError:  # a thread that ended meanwhile
            before.pop(tid, None)
    try:
        yield
    finally:
        own = before.get(threading.get_native_id(), 0)
        for tid in map(int, os.listdir("/proc/self/task")):  # a thread started meanwhile too
            with contextlib.suppress(ProcessLookupError):
                os.setpriority(os.PRIO_PROCESS, tid, before.get(tid, own))
