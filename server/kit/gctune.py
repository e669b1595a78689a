"""The cyclic garbage collector tuned for a server that holds many long-lived sockets.

At 1,000 UAVs × 10 Hz a server process with CPython's default thresholds (700, 10, 10) ran a
full (generation 2) collection every second or two, over ~350,000 objects — everything imported
at start-up plus the sessions — and each one stopped the event loop for 240-400 ms: that was the
p99 latency. Most of what the hot path allocates is freed by reference counting at once, so:

- after start-up, one collection, then `gc.freeze()`: what the imports and the start-up made goes
  to the permanent generation, and no collection walks it again;
- a young collection only after `threshold0` more container objects than were freed (20,000, not
  700), which also keeps short-lived objects that are alive at the moment of a collection (a
  batch waiting to be stored) from being promoted towards generation 2;
- generation 2 still runs (cyclic garbage is collected), after `threshold0 × threshold1 ×
  threshold2` net allocations at the earliest.

`tuned()` undoes itself on exit (the thresholds restored, the frozen objects back in generation
2), so servers started inside a test process leave it as they found it; nested or concurrent
servers in one process count, and the last one out restores.
"""

from __future__ import annotations

import gc
import threading
from collections.abc import Iterator
from contextlib import contextmanager

THRESHOLDS = (20_000, 20, 10)

_lock = threading.Lock()
_users = 0
_saved: tuple[int, int, int] | None = None


@contextmanager
def tuned(enabled: bool = True, thresholds: tuple[int, int, int] = THRESHOLDS) -> Iterator[None]:
    """Freeze what exists now and raise the collection thresholds while the block runs."""
    global _users, _saved
    if not enabled:
        yield
        return
    with _lock:
        if _users == 0:
            _saved = gc.get_threshold()
            gc.collect()
            gc.freeze()
            gc.set_threshold(*thresholds)
        _users += 1
    try:
        yield
    finally:
        with _lock:
            _users -= 1
            if _users == 0 and _saved is not None:
                gc.set_threshold(*_saved)
                gc.unfreeze()
                _saved = None
