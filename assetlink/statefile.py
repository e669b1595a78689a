"""The link's state file itself: one SQLite database, readable by its owner only, in WAL mode.

`StateFile` creates the tables, runs re-entrant BEGIN IMMEDIATE transactions and keeps
free-form key/values (`meta`); `assetlink.outbox.Outbox` builds the outbox queue, the session
token and the command ledger on it, so that queueing a command result and recording it in the
ledger are one transaction.
"""

from __future__ import annotations

import os
import sqlite3
from pathlib import Path
from typing import Any

SCHEMA = """
CREATE TABLE IF NOT EXISTS meta (key TEXT PRIMARY KEY, value TEXT NOT NULL);
CREATE TABLE IF NOT EXISTS outbox (
    pos INTEGER PRIMARY KEY AUTOINCREMENT,
    seq INTEGER UNIQUE,
    id TEXT NOT NULL,
    type TEXT NOT NULL,
    ts INTEGER NOT NULL,
    re TEXT,
    payload TEXT NOT NULL
);
CREATE TABLE IF NOT EXISTS commands (
    id TEXT PRIMARY KEY,
    name TEXT NOT NULL,
    received_ms INTEGER NOT NULL,
    state TEXT NOT NULL,
    progress TEXT,
    result TEXT
);
"""


class StateFileError(OSError):
    """The state file cannot be opened or created: a deployment's mistake, said in one line."""


class StateFile:
    """The SQLite file of one link, its transactions and its key/values; one thread only."""

    def __init__(self, path: str | Path, synchronous: str = "NORMAL"):
        """Open (or create) the state file at `path` with the given `PRAGMA synchronous`."""
        if synchronous.upper() not in ("OFF", "NORMAL", "FULL", "EXTRA"):
            raise ValueError(f"bad synchronous mode {synchronous!r}")
        # It holds the session token: readable by its owner only (SQLite gives the
        # -wal and -shm files the database file's permissions).
        try:
            os.close(os.open(path, os.O_CREAT | os.O_RDWR, 0o600))
            os.chmod(path, 0o600)
        except OSError as err:
            raise StateFileError(
                f"cannot open the state file {path}: {err.strerror}"
                " (its folder must exist and be writable by the daemon's user)"
            ) from err
        self._db = sqlite3.connect(str(path), isolation_level=None, check_same_thread=False)
        self._db.execute("PRAGMA journal_mode=WAL")
        self._db.execute(f"PRAGMA synchronous={synchronous.upper()}")
        self._db.executescript(SCHEMA)

    def _tx(self) -> _Tx:
        return _Tx(self._db)

    def _meta(self, key: str) -> str | None:
        row = self._db.execute("SELECT value FROM meta WHERE key = ?", (key,)).fetchone()
        return None if row is None else row[0]

    def _set(self, key: str, value: str) -> None:
        self._db.execute(
            "INSERT INTO meta (key, value) VALUES (?, ?) "
            "ON CONFLICT(key) DO UPDATE SET value = excluded.value",
            (key, value),
        )

    def _bump(self, key: str, by: int) -> None:
        self._set(key, str(int(self._meta(key) or 0) + by))

    def meta(self, key: str) -> str | None:
        """A free-form value kept in the state file."""
        return self._meta(key)

    def set_meta(self, key: str, value: str | None) -> None:
        """Keep a free-form value in the state file (None: forget it)."""
        with self._tx():
            if value is None:
                self._db.execute("DELETE FROM meta WHERE key = ?", (key,))
            else:
                self._set(key, value)

    def close(self) -> None:
        """Close the database."""
        self._db.close()


class _Tx:
    """BEGIN IMMEDIATE ... COMMIT, rolled back on error; re-entrant."""

    def __init__(self, db: sqlite3.Connection):
        self._db = db
        self._outer = False

    def __enter__(self) -> None:
        self._outer = not self._db.in_transaction
        if self._outer:
            self._db.execute("BEGIN IMMEDIATE")

    def __exit__(self, exc_type: Any, *_: Any) -> None:
        if not self._outer:
            return
        self._db.execute("ROLLBACK" if exc_type else "COMMIT")
