"""Fixtures for the daemon tests (helpers live in bs_helpers.py, a unique module name)."""

from bs_helpers import rig

__all__ = ["rig"]
