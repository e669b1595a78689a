"""Tests run at the CPU priority their marker asks for, so that the real-time ones keep up.

`make test` runs three workers on two cores. Most end-to-end tests fly the simulated world in
real time at a speed factor, against an agent whose detection and LANDING_TARGETs must keep up
with it; a test marked `cpu_bound` (the precision-landing evaluation flown in simulated time, the
schema fuzz) only needs the CPU, whenever it comes. Beside two such tests, on a machine where a
plain 20 M-addition Python loop takes 3.0-3.7 s, the windy LANDING_TARGET landing sent its targets
at 11.4 Hz and took 148 s, 2.7 cm off (in one full run: 7.5 Hz, 7.4 cm, off the 5 cm contacts);
with them at nice 19, 12.9 Hz in 87 s, 1.1 cm, as alone (16.1 Hz, 95 s, 1.6 cm).

A test marked `realtime` closes a landing loop through the camera in real time (the world's
rendered frames, the agent's detector, its LANDING_TARGETs, the simulated autopilot's PLND): its
error grows with the frames it loses to the tests beside it, a browser's or another flight's. In
one full run the server-killed landing, with RTK gone and the camera alone to land on, got 335
frames (697 alone) and came down 52.4 cm off. It runs at nice `REALTIME_NICE`: ahead of the
ordinary tests, which only wait the longer.

While such a test runs, every thread of its worker (Linux keeps a nice value per thread: the
test's, a live server's in the same process) and whatever they start is at its marker's nice
value, each back at its own after. A priority above the default, and raising one again, need
root (CAP_SYS_NICE), which CI has; elsewhere the priority is left alone.
"""

from __future__ import annotations

import contextlib
import os
import threading
from collections.abc import Iterator

import pytest

CPU_BOUND_NICE = 19
REALTIME_NICE = -10
NICE = {"cpu_bound": CPU_BOUND_NICE, "realtime": REALTIME_NICE}  # by marker


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_call(item: pytest.Item) -> Iterator[None]:
    """A marked test's call with its worker's threads at the marker's priority."""
    nice = next((n for m, n in NICE.items() if item.get_closest_marker(m) is not None), None)
    if nice is None or os.geteuid() != 0:
        yield
        return
    before = {}
    for tid in map(int, os.listdir("/proc/self/task")):
        try:
            before[tid] = os.getpriority(os.PRIO_PROCESS, tid)
            os.setpriority(os.PRIO_PROCESS, tid, nice)
        except ProcessLookupError:  # a thread that ended meanwhile
            before.pop(tid, None)
    try:
        yield
    finally:
        own = before.get(threading.get_native_id(), 0)
        for tid in map(int, os.listdir("/proc/self/task")):  # a thread started meanwhile too
            with contextlib.suppress(ProcessLookupError):
                os.setpriority(os.PRIO_PROCESS, tid, before.get(tid, own))
