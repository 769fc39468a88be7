"""The tables of a run store (format 1, described in :mod:`corl.store`)."""

from __future__ import annotations

import sqlite3

_SCHEMA = (
    "CREATE TABLE meta (key TEXT PRIMARY KEY, value TEXT NOT NULL)",
    """CREATE TABLE runs (
        id INTEGER PRIMARY KEY AUTOINCREMENT,
        created TEXT NOT NULL,
        task TEXT NOT NULL,
        method TEXT NOT NULL,
        seed INTEGER,
        config TEXT NOT NULL,
        versions TEXT NOT NULL,
        status TEXT NOT NULL CHECK (status IN ('running', 'finished')))""",
    """CREATE TABLE trials (
        run_id INTEGER NOT NULL REFERENCES runs (id),
        trial_index INTEGER NOT NULL CHECK (trial_index >= 0),
        step TEXT NOT NULL,
        round INTEGER NOT NULL,
        w BLOB NOT NULL,
        w_shape TEXT NOT NULL,
        theta BLOB NOT NULL,
        theta_shape TEXT NOT NULL,
        proposed_at TEXT NOT NULL,
        UNIQUE (run_id, trial_index))""",
    """CREATE TABLE outcomes (
        run_id INTEGER NOT NULL,
        trial_index INTEGER NOT NULL,
        success INTEGER NOT NULL CHECK (success IN (0, 1)),
        return_ REAL CHECK (success = 0 OR return_ IS NOT NULL),
        info TEXT NOT NULL,
        told_at TEXT NOT NULL,
        UNIQUE (run_id, trial_index),
        FOREIGN KEY (run_id, trial_index) REFERENCES trials (run_id, trial_index))""",
)


def _holds(db: sqlite3.Connection, table: str, run_id: int, index: int) -> bool:
    """Whether ``table`` ("trials" or "outcomes") has a row for trial ``index`` of the run."""
    sql = f"SELECT 1 FROM {table} WHERE run_id = ? AND trial_index = ?"
    return db.execute(sql, (run_id, index)).fetchone() is not None
