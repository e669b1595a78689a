"""Missions: waypoint lists and survey areas, QGroundControl/WPL import and export, validation."""
