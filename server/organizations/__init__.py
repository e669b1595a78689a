"""Organisations, users and their memberships with roles."""
