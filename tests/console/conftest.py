"""The console tests' browser: one headless Chromium per test module (tests/console/browser.py)."""

from __future__ import annotations

import pytest

from tests.console.browser import launch


@pytest.fixture(scope="module")
async def browser():  # type: ignore[no-untyped-def]
    async for b in launch():
        yield b
