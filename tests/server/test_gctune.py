"""The garbage collector tuning of a started server: applied while it runs, undone when it stops.

The process may already hold a tuned server (the session's live server): each test compares with
the state it found, which is then the one the last server out restores."""

from __future__ import annotations

import gc

from server.kit import gctune
from tests.conftest import LiveServer, test_settings


def state() -> tuple[tuple[int, int, int], bool]:
    return gc.get_threshold(), gc.get_freeze_count() > 0


def test_a_running_server_freezes_start_up_and_raises_the_thresholds(database_url: str) -> None:
    before = state()
    server = LiveServer(test_settings(database_url)).start()
    try:
        assert gc.get_threshold() == gctune.THRESHOLDS
        assert gc.get_freeze_count() > 10_000  # the imports and the app: not walked again
    finally:
        server.stop()
    assert state() == before


def test_nested_users_restore_only_when_the_last_leaves() -> None:
    before = state()
    with gctune.tuned():
        with gctune.tuned():
            assert gc.get_threshold() == gctune.THRESHOLDS
        assert gc.get_threshold() == gctune.THRESHOLDS
        assert gc.get_freeze_count() > 0
    assert state() == before


def test_switched_off_it_changes_nothing() -> None:
    before = state()
    with gctune.tuned(enabled=False):
        assert state() == before
