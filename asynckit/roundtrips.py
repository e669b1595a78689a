"""Round-trip times of one kind of exchange (a PLC read, a MAVLink command and its ACK), kept as
a count, a sum and the latest value: what a Prometheus summary needs, and nothing that grows."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass
class RoundTrips:
    """Count, total and latest round-trip time in seconds."""

    count: int = 0
    total_s: float = 0.0
    last_s: float | None = None

    def observe(self, seconds: float) -> None:
        """Record one exchange that took `seconds`."""
        self.count += 1
        self.total_s += seconds
        self.last_s = seconds
