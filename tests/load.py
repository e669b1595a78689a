"""A busy machine for load-sensitive tests: processes that spin a core each beside the test."""

from __future__ import annotations

import contextlib
import subprocess
import sys
from collections.abc import Iterator


@contextlib.contextmanager
def busy_processes(n: int = 4) -> Iterator[list[subprocess.Popen[bytes]]]:
    """`n` Python processes spinning at the default priority while the block runs."""
    procs = [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(n)]
    try:
        yield procs
    finally:
        for proc in procs:
            proc.kill()
        for proc in procs:
            proc.wait()
