"""Airspace: organisation zones, per-base operating areas, and checking a mission's path against them."""
