"""The run report's landing part from the agent's `landed` and the base's `landing_confirmed` (pure)."""

from __future__ import annotations

from datetime import UTC, datetime

from server.runs.service import landing_report
from server.telemetry.models import AssetEvent

T = datetime(2026, 11, 24, 3, 14, tzinfo=UTC)


def _event(name: str, data: object) -> AssetEvent:
    return AssetEvent(name=name, ts=T, severity="info", message="", data=data)


def test_both_machines_reported():
    landing = landing_report(
        _event("landed", {"offset_source": "precland", "offset_m": 0.012, "offset_north_m": 0.01,
                          "offset_east_m": -0.007, "fix_height_m": 0.4, "fix_age_s": 0.8,
                          "fix_sources": "pattern+ir", "landing_path": "search-then-precision"}),
        _event("landing_confirmed", {"mass_g": 1451.0}),
    )  # fmt: skip
    assert landing is not None
    assert (landing.agent_offset_m, landing.agent_fix_sources) == (0.012, "pattern+ir")
    assert landing.agent_landing_path == "search-then-precision"
    assert landing.base_confirmed and landing.base_mass_g == 1451.0 and landing.landed_at == T


def test_a_landing_without_a_fix_or_with_junk_data_has_no_offset():
    for data in ({"offset_source": "none"}, {"offset_m": float("nan")}, {"offset_m": "far"}, []):
        landing = landing_report(_event("landed", data), None)
        assert landing is not None and landing.agent_offset_m is None and not landing.base_confirmed
        assert landing.agent_landing_path is None
    assert landing_report(None, None) is None
