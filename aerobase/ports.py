"""Picking a port for a program started later (the demo's processes, a test's server).

A port the kernel hands out for `bind(("127.0.0.1", 0))` comes from its ephemeral range
(`net.ipv4.ip_local_port_range`, 32768-60999 by default), the range it also takes every
outgoing connection's local port from. Closed and given to a program that binds it a moment
later, such a port can meanwhile have become the local end of someone else's connection (a
database client, an HTTP client of a parallel test) and the bind fails with EADDRINUSE. So
`free_port` picks below that range, where the kernel never assigns a port by itself, at random
(several test workers pick at once) among the ports free for both TCP and UDP right now.
"""

from __future__ import annotations

import random
import socket
from pathlib import Path

PICK_FROM = 15000  # the lowest port picked: above the well-known services' defaults
RANGE_FILE = Path("/proc/sys/net/ipv4/ip_local_port_range")
TRIES = 100
_pick = random.SystemRandom()  # not the `random` a test seeds: parallel workers would pick alike


def ephemeral_low() -> int:
    """The lowest port the kernel assigns by itself (32768 where it cannot be read)."""
    try:
        return int(RANGE_FILE.read_text().split()[0])
    except (OSError, ValueError, IndexError):
        return 32768


def port_free(port: int, kind: int = socket.SOCK_STREAM) -> bool:
    """Whether `port` on 127.0.0.1 can be bound right now (TCP by default)."""
    with socket.socket(socket.AF_INET, kind) as s:
        try:
            s.bind(("127.0.0.1", port))
        except OSError:
            return False
    return True


def free_port() -> int:
    """A port free on 127.0.0.1 right now for TCP and UDP, outside the ephemeral range when
    there is room below it (else the kernel's own pick)."""
    high = ephemeral_low()
    if high - PICK_FROM >= 1000:
        for _ in range(TRIES):
            port = _pick.randrange(PICK_FROM, high)
            if port_free(port) and port_free(port, socket.SOCK_DGRAM):
                return port
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])
