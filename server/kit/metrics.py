"""Prometheus metrics of one server process, exposed on `/metrics` (prometheus-client's text format).

Counters and histograms are updated where things happen (HTTP middleware, command status
changes, run transitions, lease claims, the ingest); the live connections and the realtime
counters are read from the hubs at scrape time. Every replica reports its own process: sum over
replicas in Prometheus. Run and command figures are counted by the replica that wrote them.
"""

from __future__ import annotations

import logging
import time
import uuid
import weakref
from collections.abc import Iterator
from typing import Any, Protocol

import structlog
from prometheus_client import CollectorRegistry, Counter, Gauge, Histogram
from prometheus_client.core import CounterMetricFamily, GaugeMetricFamily, Metric
from prometheus_client.registry import Collector
from starlette.types import ASGIApp, Message, Receive, Scope, Send

REGISTRY = CollectorRegistry()
access = logging.getLogger("aerobase.access")

HTTP_LATENCY = Histogram(
    "aerobase_http_request_duration_seconds",
    "HTTP request latency by method, route template and status",
    ["method", "route", "status"],
    registry=REGISTRY,
)
COMMANDS = Counter(
    "aerobase_commands_total",
    "Commands reaching a final status, by command name and status",
    ["name", "status"],
    registry=REGISTRY,
)
COMMAND_LATENCY = Histogram(
    "aerobase_command_latency_seconds",
    "From a command's creation to its final status, by command name and status",
    ["name", "status"],
    buckets=(0.1, 0.25, 0.5, 1, 2.5, 5, 10, 30, 60, 120, 300, 600),
    registry=REGISTRY,
)
RUNS = Counter(
    "aerobase_runs_total",
    "Runs that ended, by outcome (completed, completed_with_issues, incomplete, aborted, "
    "failed) and cause",
    ["outcome", "cause"],
    registry=REGISTRY,
)
RUN_STEP = Histogram(
    "aerobase_run_step_duration_seconds",
    "Time spent in each step of a run, observed when the run leaves it",
    ["step"],
    buckets=(0.5, 1, 2.5, 5, 10, 30, 60, 120, 300, 600, 1800),
    registry=REGISTRY,
)
LEASE_TAKEOVERS = Counter(
    "aerobase_run_lease_takeovers_total",
    "Runs this process leased after another process's lease ran out",
    registry=REGISTRY,
)
INGEST_LAG = Histogram(
    "aerobase_ingest_lag_seconds",
    "From the arrival of a stored batch's oldest durable message to the batch being stored "
    "(one observation per batch: the worst lag in it)",
    buckets=(0.005, 0.01, 0.025, 0.05, 0.1, 0.25, 0.5, 1, 2.5, 5),
    registry=REGISTRY,
)
BASE_PLC_LINK = Gauge(
    "aerobase_base_plc_link_up",
    "1 when a landing base's daemon last reported its PLC link up",
    ["asset_id"],
    registry=REGISTRY,
)
VIDEO_FRAMES = Counter(
    "aerobase_video_frames_forwarded_total",
    "Encoded video frames the embedded relay handed to a viewer or a recorder (never re-encoded)",
    registry=REGISTRY,
)
VIDEO_VIEWERS = Gauge(
    "aerobase_video_viewers",
    "Video viewer sessions held by this process's embedded relay",
    registry=REGISTRY,
)
VIDEO_PUBLISHERS = Gauge(
    "aerobase_video_publishers",
    "Assets publishing video to this process's embedded relay",
    registry=REGISTRY,
)
NTRIP_CLIENTS = Gauge(
    "aerobase_ntrip_clients",
    "Rovers streaming a base's corrections from this process, by NTRIP version (the caster's "
    "own port serves both; /ntrip/ on the HTTP port serves version 2)",
    ["version"],
    registry=REGISTRY,
)
NTRIP_RECHECKS = Counter(
    "aerobase_ntrip_rechecks_total",
    "Running NTRIP streams' credentials checked again, by outcome: allowed, ended (the account "
    "may no longer take the stream), failed (could not be checked, the database away: the "
    "stream goes on)",
    ["outcome"],
    registry=REGISTRY,
)
LOGINS = Counter(
    "aerobase_logins_total",
    "Password and secret checks by door (user, asset, ntrip, password_change) and outcome: ok "
    "(the right one), wrong, repeated (a wrong password sent again: answered, not counted), "
    "limited (refused by the failed-login limits)",
    ["door", "outcome"],
    registry=REGISTRY,
)
BASE_RTK_RATE = Gauge(
    "aerobase_base_rtk_corrections_per_second",
    "RTCM3 correction frames per second a landing base last reported",
    ["asset_id"],
    registry=REGISTRY,
)
BASE_RTK_AGE = Gauge(
    "aerobase_base_rtk_correction_age_seconds",
    "Age of the last good RTCM3 frame a landing base last reported (absent before its first)",
    ["asset_id"],
    registry=REGISTRY,
)


class HubView(Protocol):
    """What the scrape reads from a realtime hub."""

    connected: Any  # collections.Counter[str]: live sockets by kind ("asset", "operator")
    counters: Any  # server.realtime.hub.Counters


class _Hubs(Collector):
    """Connections and realtime counters, summed over the live hubs of this process."""

    def __init__(self) -> None:
        self.hubs: weakref.WeakSet[Any] = weakref.WeakSet()

    def collect(self) -> Iterator[Metric]:
        hubs = list(self.hubs)
        assets = GaugeMetricFamily("aerobase_connected_assets", "Assets with a live socket here")
        assets.add_metric([], sum(h.connected["asset"] for h in hubs))
        operators = GaugeMetricFamily(
            "aerobase_connected_operators", "Operator sockets open on this process"
        )
        operators.add_metric([], sum(h.connected["operator"] for h in hubs))
        received = CounterMetricFamily(
            "aerobase_telemetry_messages_received",
            "Messages received from assets, by outcome",
            labels=["outcome"],
        )
        for outcome, attr in (
            ("accepted", "received"),
            ("duplicate", "duplicates"),
            ("malformed", "malformed"),
            ("rate_limited", "rate_limited"),
        ):
            received.add_metric([outcome], sum(getattr(h.counters, attr) for h in hubs))
        sent = CounterMetricFamily(
            "aerobase_telemetry_messages_sent",
            "Messages sent to operators, and those dropped for a slow reader",
            labels=["outcome"],
        )
        sent.add_metric(["sent"], sum(h.counters.sent_to_operators for h in hubs))
        sent.add_metric(["dropped"], sum(h.counters.operator_dropped for h in hubs))
        yield from (assets, operators, received, sent)


HUBS = _Hubs()
REGISTRY.register(HUBS)


def watch_hub(hub: HubView) -> None:
    """Report this hub's connections and counters on /metrics (until it is garbage)."""
    HUBS.hubs.add(hub)


class ObserveRequests:
    """ASGI middleware for every HTTP request: a request id (the proxy's `X-Request-Id`, else a new
    one) bound to every log line written while it is served and echoed in the response; one
    access-log line; latency by route template (`/api/v1/runs/{run_id}`, never the id)."""

    def __init__(self, app: ASGIApp) -> None:
        self.app = app

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        request_id = _request_id(scope)
        status = 500
        start = time.perf_counter()

        async def sending(message: Message) -> None:
            nonlocal status
            if message["type"] == "http.response.start":
                status = int(message["status"])
                message = {
                    **message,
                    "headers": [
                        *message.get("headers", []),
                        (b"x-request-id", request_id.encode()),
                    ],
                }
            await send(message)

        with structlog.contextvars.bound_contextvars(request_id=request_id):
            try:
                await self.app(scope, receive, sending)
            finally:
                elapsed = time.perf_counter() - start
                route = getattr(scope.get("route"), "path", None) or "unmatched"
                HTTP_LATENCY.labels(scope["method"], route, str(status)).observe(elapsed)
                access.info(
                    "%s %s %d",
                    scope["method"],
                    route,
                    status,
                    extra={"duration_ms": round(elapsed * 1000, 1)},
                )


def _request_id(scope: Scope) -> str:
    """The caller's (the proxy's) request id when it is a sane token, else a new one."""
    for name, value in scope.get("headers", ()):
        if name == b"x-request-id":
            text = value.decode("latin-1")
            if 0 < len(text) <= 64 and all(c.isalnum() or c in "-_." for c in text):
                return text
    return uuid.uuid4().hex
