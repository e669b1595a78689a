"""The search for a pad not in view and its fallback (issue 19 item 2): the expanding square, and
the sequence's acquire → search → found / RTK fallback / climb-and-report, with its `path`."""

from __future__ import annotations

import itertools
import math

import pytest

from asset_agent.precland.config import CameraModel, ControlConfig, RetryConfig, SearchConfig
from asset_agent.precland.kalman import FIX_3D, FIX_RTK_FIXED, FIX_RTK_FLOAT
from asset_agent.precland.search import ExpandingSquare, corners, leg_spacing
from asset_agent.precland.sequence import LandingSequence

C = ControlConfig()
CAMERA = CameraModel()


def test_legs_grow_by_the_cameras_footprint_and_stop_at_the_radius():
    s = SearchConfig(footprint_fraction=0.8, pad_half_size_m=0.55)
    # the narrower image axis at 10 m: 10 x 239.5 / 460 = 5.21 m each side, less the pad
    assert leg_spacing(10.0, CAMERA, s) == pytest.approx(0.8 * 2 * (10 * 239.5 / 460 - 0.55))
    assert leg_spacing(0.5, CAMERA, s) == s.min_leg_m  # nothing in view that low
    pts = corners((1.0, 2.0), 3.0, 10.0)
    legs = [math.dist(a, b) for a, b in itertools.pairwise(pts)]
    assert pts[0] == (1.0, 2.0)
    assert legs[:6] == pytest.approx([3, 3, 6, 6, 9, 9])  # north, east, south, west, ...
    assert pts[1] == (4.0, 2.0) and pts[2] == (4.0, 5.0) and pts[3] == (-2.0, 5.0)
    # bounded: no corner further than the radius north or east of the centre, and the leg that
    # would cross it ends on it
    assert max(max(abs(n - 1.0), abs(e - 2.0)) for n, e in pts) == pytest.approx(10.0)
    assert legs[-1] < (len(legs) // 2 + 1) * 3.0


def test_the_search_advances_past_reached_corners_and_ends_by_time_or_pattern():
    sq = ExpandingSquare.start(0.0, (0.0, 0.0), 5.0, CAMERA, SearchConfig(max_time_s=30.0))
    assert sq.target(0.0, (2.0, 0.0)) == (0.0, 0.0)  # the surveyed position first
    assert sq.target(1.0, (0.1, 0.0)) == sq.waypoints[1]
    assert sq.target(31.0, (0.0, 0.0)) is None  # time is up
    sq = ExpandingSquare.start(0.0, (0.0, 0.0), 5.0, CAMERA, SearchConfig(max_time_s=1e9))
    for wp in sq.waypoints:
        sq.target(1.0, wp)
    assert sq.target(1.0, sq.waypoints[-1]) is None  # every corner flown


def fly(seq: LandingSequence, t: float, seen: bool, rel, vehicle, fix: int | None = FIX_3D):
    return seq.step(t, seen, rel, 0.0, vehicle, 0.0, gnss_fix=fix)


def searching(search: SearchConfig | None = None) -> LandingSequence:
    """A sequence that never saw the pad, 10 m over its surveyed position (local 5, 5)."""
    seq = LandingSequence(C, RetryConfig(), search or SearchConfig(acquire_s=2.0), CAMERA)
    cmd = fly(seq, 0.0, False, (0.0, 0.0, 10.0), (5.0, 5.0))
    assert cmd.state == "acquire" and (cmd.setpoint.vn, cmd.setpoint.vd) == (0, 0)  # hover
    assert fly(seq, 1.9, False, (0.0, 0.0, 10.0), (5.0, 5.0)).state == "acquire"
    cmd = fly(seq, 2.0, False, (0.0, 0.0, 10.0), (5.0, 5.0))
    assert cmd.state == "search" and seq.path == "gnss"
    return seq


def test_a_pad_found_by_the_search_is_landed_on_by_precision():
    seq = searching()
    # at the centre, the first leg goes north at the search speed, holding the height
    cmd = fly(seq, 2.1, False, (0.0, 0.0, 10.0), (5.0, 5.0))
    assert cmd.setpoint.vn == pytest.approx(SearchConfig().speed) and cmd.setpoint.ve == 0
    assert cmd.setpoint.vd == 0
    cmd = fly(seq, 3.0, False, (0.0, 0.0, 10.5), (6.0, 5.0))
    assert cmd.setpoint.vd > 0  # back down to the search height
    cmd = fly(seq, 4.0, True, (-3.0, 1.0, 10.0), (8.0, 4.0))  # in view: centre, descend
    assert cmd.state == "approach" and seq.path == "search-then-precision"
    assert cmd.setpoint.vn < 0 and cmd.setpoint.ve > 0
    cmd = fly(seq, 30.0, True, (0.0, 0.0, 0.26), (5.0, 5.0))
    assert cmd.setpoint.land and seq.state == "landed" and seq.path == "search-then-precision"


def over(seq: LandingSequence, fix: int) -> None:
    """Fly every corner of the search without seeing the pad."""
    square = seq._square
    assert square is not None
    for i, wp in enumerate(square.waypoints[:-1]):
        assert fly(seq, 3.0 + i, False, (0.0, 0.0, 10.0), wp, fix).state == "search"
    fly(seq, 3.0 + len(square.waypoints), False, (0.0, 0.0, 10.0), square.waypoints[-1], fix)


def test_searched_in_vain_on_rtk_fixed_it_lands_on_gnss_over_the_surveyed_pad():
    seq = searching()
    over(seq, FIX_RTK_FIXED)
    assert seq.state == "fallback" and seq.path == "rtk-fallback"
    cmd = fly(seq, 100.0, False, (0.3, -0.2, 10.0), (5.3, 4.8), FIX_RTK_FIXED)
    assert cmd.setpoint.vd > 0 and cmd.setpoint.vn > 0 and cmd.setpoint.ve < 0  # to the pad
    # in view lower down: precision takes over; the path still says how it got there
    assert fly(seq, 110.0, True, (0.1, 0.0, 2.9), (5.0, 5.0), FIX_RTK_FIXED).state == "approach"
    fly(seq, 120.0, True, (0.0, 0.0, 0.26), (5.0, 5.0), FIX_RTK_FIXED)
    assert seq.state == "landed" and seq.path == "rtk-fallback"


@pytest.mark.parametrize("fix", [FIX_RTK_FLOAT, FIX_3D, None])
def test_searched_in_vain_without_rtk_fixed_it_climbs_and_holds_never_landing_blind(fix):
    search = SearchConfig(acquire_s=2.0, abort_height_m=15.0)
    seq = searching(search)
    over(seq, fix)
    assert seq.state == "abort" and seq.path == "aborted-climb" and not seq.holding_safe
    assert seq.abort_reason == "pad not found, no RTK fix"
    cmd = fly(seq, 100.0, False, (0.0, 0.0, 10.0), (5.0, 5.0), fix)
    assert cmd.setpoint.vd < 0 and not cmd.setpoint.land  # climbing
    # the pad coming into view does not bring it down again: the operator decides
    assert fly(seq, 101.0, True, (0.0, 0.0, 11.0), (5.0, 5.0), fix).state == "abort"
    cmd = fly(seq, 110.0, False, (0.0, 0.0, 15.0), (5.0, 5.0), fix)
    assert seq.holding_safe and cmd.setpoint.vd == 0 and seq.path == "aborted-climb"


def test_the_fallback_climbs_when_the_fix_degrades_on_the_way_down():
    seq = searching()
    over(seq, FIX_RTK_FIXED)
    assert fly(seq, 100.0, False, (0.0, 0.0, 6.0), (5.0, 5.0), FIX_RTK_FIXED).state == "fallback"
    assert fly(seq, 101.0, False, (0.0, 0.0, 5.5), (5.0, 5.0), FIX_RTK_FLOAT).state == "abort"
    assert seq.abort_reason == "RTK fix lost on the way down"


def test_a_pad_in_view_from_the_start_is_a_precision_landing_and_no_search():
    seq = LandingSequence(C, RetryConfig(), SearchConfig(), CAMERA)
    assert fly(seq, 0.0, True, (0.5, 0.0, 10.0), (0.0, 0.0)).state == "approach"
    assert seq.path == "precision"
    # lost later: the cautious retries, not the search
    assert fly(seq, 1.0, False, (0.0, 0.0, 2.0), (0.0, 0.0)).state == "pause"
