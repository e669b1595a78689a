"""A daemon's own Prometheus `/metrics` on a local port (the base-station daemon and the agent).

Everything is read at scrape time from the live objects, so nothing is counted twice and the
daemon's loops pay nothing: its server link (connected, outbox depth, messages sent, acked,
replayed and dropped, reconnects) from `Link.stats`, plus the families the daemon adds (PLC or
MAVLink round trips, RTK correction age). These are one daemon's own figures; the server's
`/metrics` carries the fleet-wide ones (connected assets, what bases last reported).

Off unless a port is configured; it listens on 127.0.0.1 by default (a node exporter's habit:
scrape it on the machine, or set the host when the scraper is elsewhere on a trusted network).
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Iterable, Iterator
from typing import Any

from prometheus_client import CollectorRegistry, start_http_server
from prometheus_client.core import (
    CounterMetricFamily,
    GaugeMetricFamily,
    Metric,
    SummaryMetricFamily,
)
from prometheus_client.registry import Collector

from assetlink.link import Link
from asynckit.roundtrips import RoundTrips

log = logging.getLogger(__name__)

Families = Callable[[], Iterable[Metric]]


def gauge(name: str, doc: str, value: float | None) -> Iterator[Metric]:
    """One unlabelled gauge; nothing when there is no value yet."""
    if value is not None:
        family = GaugeMetricFamily(name, doc)
        family.add_metric([], value)
        yield family


def round_trips(name: str, doc: str, trips: RoundTrips) -> Iterator[Metric]:
    """A summary (`_count`, `_sum`) of round trips, and the latest one as `<name>_last`."""
    summary = SummaryMetricFamily(name, doc)
    summary.add_metric([], count_value=trips.count, sum_value=trips.total_s)
    yield summary
    yield from gauge(f"{name}_last", f"{doc} (the latest)", trips.last_s)


class DaemonMetrics(Collector):
    """The families of one daemon: its server link's, then `extra`'s."""

    def __init__(self, link: Link, extra: Families | None = None) -> None:
        self.link = link
        self.extra = extra

    def collect(self) -> Iterator[Metric]:
        try:
            stats = self.link.stats
        except RuntimeError:  # not started yet
            stats = None
        if stats is not None:
            yield from gauge(
                "aerobase_server_link_up",
                "1 while the link to the server is connected",
                float(self.link.connected),
            )
            yield from gauge(
                "aerobase_outbox_depth",
                "Durable messages queued on disk and not yet acknowledged by the server",
                stats.queued,
            )
            messages = CounterMetricFamily(
                "aerobase_outbox_messages",
                "Durable messages by outcome: sent (with replays), acked, replayed, dropped at "
                "the outbox bound",
                labels=["outcome"],
            )
            for outcome in ("sent", "acked", "replayed", "dropped"):
                messages.add_metric([outcome], getattr(stats, outcome))
            yield messages
            reconnects = CounterMetricFamily(
                "aerobase_server_link_reconnects", "Sessions with the server after the first"
            )
            reconnects.add_metric([], stats.reconnects)
            yield reconnects
        if self.extra is not None:
            yield from self.extra()


class MetricsServer:
    """`/metrics` of one collector on host:port, served from a thread; `close()` stops it."""

    def __init__(self, collector: Collector, host: str, port: int) -> None:
        registry = CollectorRegistry()
        registry.register(collector)
        self._server: Any
        self._server, self._thread = start_http_server(port, host, registry)
        self.port = int(self._server.server_address[1])
        log.info("metrics on http://%s:%d/metrics", host, self.port)

    def close(self) -> None:
        """Stop serving and release the port."""
        self._server.shutdown()
        self._server.server_close()
        self._thread.join(5)
