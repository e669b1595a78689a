"""The landing-base daemon's own Prometheus families (served by assetlink.metrics beside its
server link's): the PLC link and its read round trips, the RTK reference stream's state, rate
and correction age. Read at scrape time; one daemon's figures (the server's /metrics has what
every base last reported)."""

from __future__ import annotations

from collections.abc import Iterator

from prometheus_client.core import CounterMetricFamily, GaugeMetricFamily, Metric

from assetlink.metrics import gauge, round_trips
from assetlink.rtk import RtkReader, rtk_state
from base_station.coordinator import Coordinator

RTK_STATES = ("disconnected", "waiting", "stale", "streaming")


def families(coordinator: Coordinator, reader: RtkReader | None) -> Iterator[Metric]:
    """PLC and RTK families of this daemon now."""
    snap = coordinator.snapshot
    yield from gauge(
        "aerobase_plc_link_up",
        "1 while the PLC answers and its heartbeat moves",
        float(snap.link_up),
    )
    yield from round_trips(
        "aerobase_plc_read_round_trip_seconds",
        "One poll's Modbus TCP read of the PLC's state, request to answer",
        coordinator.read_round_trips,
    )
    polls = CounterMetricFamily("aerobase_plc_polls", "PLC polls, answered or not")
    polls.add_metric([], coordinator.polls)
    yield polls
    if reader is None:
        return
    stats = reader.stats()
    state = GaugeMetricFamily(
        "aerobase_rtk_state", "1 for the RTK correction stream's current state", labels=["state"]
    )
    now = rtk_state(stats)
    for name in RTK_STATES:
        state.add_metric([name], float(name == now))
    yield state
    yield from gauge(
        "aerobase_rtk_correction_age_seconds",
        "Since the last good RTCM3 frame from the reference receiver (absent before the first)",
        stats.last_frame_age_s,
    )
    yield from gauge(
        "aerobase_rtk_corrections_per_second", "RTCM3 frames per second lately", stats.frames_per_s
    )
    frames = CounterMetricFamily(
        "aerobase_rtk_frames", "RTCM3 frames by outcome", labels=["outcome"]
    )
    frames.add_metric(["good"], stats.good_frames)
    frames.add_metric(["bad"], stats.bad_frames)
    yield frames
