"""The store at rest is one file: SQLite's write-ahead log (-wal, -shm beside it) only while a writer
has it open. These helpers find, fold and remove a log a killed writer left behind (:mod:`corl.store.sqlite`)."""

from __future__ import annotations

import os
import sqlite3
from pathlib import Path

_FOLD_TIMEOUT_S = 0.2  # how long close() waits for readers before leaving the log to the next command


def _sidecar(path: Path, suffix: str) -> Path:
    return path.with_name(path.name + suffix)


def _writable(path: Path) -> bool:
    """Whether SQLite can create its -shm beside ``path`` and write ``path``."""
    return os.access(path.parent, os.W_OK | os.X_OK) and os.access(path, os.W_OK)


def _log_holds_data(path: Path) -> bool:
    try:
        return _sidecar(path, "-wal").stat().st_size > 0
    except OSError:
        return False


def _fold_log(db: sqlite3.Connection) -> None:
    """Checkpoint the write-ahead log into the file, truncate it, and return to a rollback journal.

    Best effort: a reader holding the log open makes SQLite refuse (after a short wait); the
    trials are safe either way, and the next command that closes the store folds the log.
    """
    try:
        db.execute(f"PRAGMA busy_timeout = {int(1000 * _FOLD_TIMEOUT_S)}")
        db.execute("PRAGMA wal_checkpoint(TRUNCATE)").fetchall()
        db.execute("PRAGMA journal_mode = DELETE").fetchall()  # removes the -wal and -shm files
    except sqlite3.Error:
        pass


def _wal_header(path: Path) -> bool:
    """Whether the file's header says WAL mode (bytes 18-19 are 2), i.e. it was not closed by this corl."""
    try:
        with open(path, "rb") as f:
            return f.read(20)[18:20] == b"\x02\x02"
    except OSError:
        return False
