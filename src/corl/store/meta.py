"""What a run keeps in the meta table beside its trials: the learner's best, where it was ended, and,
with several robots, the order in which its trials went out and came back (:class:`KeptByRun`).

The pattern of a run with K robots (``config["robots"] = K > 1``)
----------------------------------------------------------------
With one robot a run alternates (trial i is asked once i outcomes are told) and replay needs nothing
more. With K robots up to K trials are pending at once, told in any order, and what the learner
proposes depends on how many outcomes it had when it was asked. The store keeps that sequence under
``pattern:<run id>``, one letter per event, each written in the transaction of what it records:

=====  =========================================================================================
``a``  a trial was handed out (trials go out in index order, so the letter needs no index)
``t``  an outcome was told (which trial's: the outcomes table's rowid order, :meth:`told_order`)
``w``  the learner was asked and had nothing to hand out before a tell (``try_ask`` returned None);
       asking can move a learner (its method decides a next point), so replay asks there too
=====  =========================================================================================

``corl serve --robots K`` also keeps which robot each trial was handed to, under ``robot:<run id>:<index>``
(the robot's name as it asked, :meth:`KeptByRun.set_holder`), so that a restarted server hands a robot's
pending trial back to that robot. A store without these keys is read as one whose trials no robot holds.
"""

from __future__ import annotations

import json
import sqlite3

from corl.store.records import RunStatus, StoreError, _as_int

__all__ = ["KeptByRun", "robots_of", "note"]


def robots_of(db: sqlite3.Connection, run_id: int) -> int:
    """K, the trials the run may have pending at once: its ``config["robots"]``, 1 when not set."""
    row = db.execute("SELECT config FROM runs WHERE id = ?", (run_id,)).fetchone()
    try:
        k = json.loads(row[0]).get("robots", 1) if row is not None else 1
    except (ValueError, AttributeError):
        return 1
    return k if isinstance(k, int) and k >= 1 else 1


def note(db: sqlite3.Connection, run_id: int, letter: str) -> None:
    """Append ``letter`` to the pattern of run ``run_id`` (a run with K > 1 only; inside a transaction).
    A ``w`` right after a ``w`` is not noted: with no tell between, a second ask finds the learner as the first."""
    if robots_of(db, run_id) == 1:
        return
    key = f"pattern:{run_id}"
    row = db.execute("SELECT value FROM meta WHERE key = ?", (key,)).fetchone()
    pattern = "" if row is None else str(row[0])
    if letter == "w" and pattern.endswith("w"):
        return
    db.execute("INSERT OR REPLACE INTO meta (key, value) VALUES (?, ?)", (key, pattern + letter))


class KeptByRun:
    """The :class:`corl.store.RunStore` methods over what a run keeps in the meta table."""

    # -- the learner's best and the run's end -----------------------------------------------------
    def set_best(self, run_id: int, best: dict | None) -> None:
        """Keep the learner's best of run ``run_id`` (JSON, :func:`corl.session.best_record`) for readers
        that do not replay the run (``corl status``); written after each told trial, so a crash between
        the two leaves it one trial behind until the run resumes."""
        self._keep(run_id, "best", best)

    def best(self, run_id: int) -> dict | None:
        """The learner's best kept by :meth:`set_best`, or None (none kept yet, or a store from before)."""
        return self._kept(run_id, "best")

    def set_end(self, run_id: int, end: dict) -> None:
        """Mark run ``run_id`` finished where the task's code raised (``corl run --resume --end-at-error``):
        ``end`` holds ``trial`` (the last told one; its follow-up raised), ``member`` and ``error``."""
        self._keep(run_id, "end", end)
        self.set_status(run_id, RunStatus.FINISHED)

    def end(self, run_id: int) -> dict | None:
        """How run ``run_id`` was ended by :meth:`set_end`, or None (it was not)."""
        return self._kept(run_id, "end")

    def _keep(self, run_id: int, key: str, value: dict | None) -> None:
        run_id = _as_int(run_id, what="run id")
        text = json.dumps(value, allow_nan=False)
        with self._transaction(f"keep the {key} of run {run_id}") as db:
            self._run_status(db, run_id)
            db.execute("INSERT OR REPLACE INTO meta (key, value) VALUES (?, ?)", (f"{key}:{run_id}", text))

    def _kept(self, run_id: int, key: str) -> dict | None:
        run_id = _as_int(run_id, what="run id")
        rows = self._read("SELECT value FROM meta WHERE key = ?", (f"{key}:{run_id}",))
        if not rows:
            return None
        try:
            value = json.loads(rows[0][0])
        except ValueError:
            raise self._damaged(f"the {key} kept for run {run_id} is not JSON") from None
        return value if isinstance(value, dict) else None

    # -- several robots: the order of asks and tells (module docstring) ---------------------------
    def note_wait(self, run_id: int) -> None:
        """Note that the learner of run ``run_id`` was asked and had no trial to hand out (``w``)."""
        run_id = _as_int(run_id, what="run id")
        with self._transaction(f"note a wait of run {run_id}") as db:
            self._run_status(db, run_id)
            note(db, run_id, "w")

    def pattern(self, run_id: int) -> str | None:
        """The run's pattern of asks (``a``), tells (``t``) and waits (``w``); None for a run with one robot."""
        run_id = self.run(run_id).id
        rows = self._read("SELECT value FROM meta WHERE key = ?", (f"pattern:{run_id}",))
        if rows:
            text = str(rows[0][0])
            if set(text) - set("atw"):
                raise self._damaged(f"the pattern of run {run_id} holds letters other than a, t, w")
            return text
        return None if self.run(run_id).config.get("robots", 1) == 1 else ""

    def told_order(self, run_id: int) -> list[int]:
        """The indices of the run's told trials in the order they were told."""
        run_id = self.run(run_id).id
        return [int(r[0]) for r in self._read("SELECT trial_index FROM outcomes WHERE run_id = ? ORDER BY rowid",
                                              (run_id,))]

    def set_holder(self, run_id: int, index: int, robot: str) -> None:
        """Keep that trial ``index`` of run ``run_id`` was handed to the robot named ``robot`` (corl serve)."""
        run_id, index = _as_int(run_id, what="run id"), _as_int(index, what="trial index")
        with self._transaction(f"keep the robot of trial {index} of run {run_id}") as db:
            self._run_status(db, run_id)
            db.execute("INSERT OR REPLACE INTO meta (key, value) VALUES (?, ?)", (f"robot:{run_id}:{index}", str(robot)))

    def holders(self, run_id: int) -> dict[int, str]:
        """Trial index -> the robot it was handed to, for the trials of run ``run_id`` kept by :meth:`set_holder`."""
        run_id = _as_int(run_id, what="run id")
        prefix = f"robot:{run_id}:"
        rows = self._read("SELECT key, value FROM meta WHERE key >= ? AND key < ?", (prefix, prefix[:-1] + ";"))
        out = {}
        for key, value in rows:
            tail = str(key)[len(prefix):]
            if tail.isdigit():
                out[int(tail)] = str(value)
        return out

    def pending_trials(self, run_id: int) -> list:
        """Every trial proposed and not told yet, in index order (up to the run's K robots)."""
        return self._records(run_id, self._TRIALS_SQL + " AND o.run_id IS NULL ORDER BY t.trial_index")

    def check_room(self, db: sqlite3.Connection, run_id: int, last: int | None, index: int) -> None:
        """Refuse trial ``index`` while as many trials are pending as the run has robots."""
        if last is None:
            return
        k = robots_of(db, run_id)
        out = db.execute("SELECT COUNT(*) FROM trials t WHERE t.run_id = ? AND NOT EXISTS (SELECT 1 FROM outcomes o "
                         "WHERE o.run_id = t.run_id AND o.trial_index = t.trial_index)", (run_id,)).fetchone()[0]
        if out >= k == 1:
            raise StoreError(f"trial {last} of run {run_id} is still pending; tell its outcome before storing "
                             f"trial {index}")
        if out >= k:
            raise StoreError(f"run {run_id} has {out} trials pending, one per robot ({k}); tell one of them before "
                             f"storing trial {index}")
