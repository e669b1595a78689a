"""Shared building blocks of the server: database, errors, scoping, security, time."""
