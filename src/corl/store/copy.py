"""Copy runs from one store into another, row for row (``corl bench contexts --robots K``: each robot
learns its scene in a store of its own, and the runs are gathered into the study's store after).

A copy holds what the source holds, as it is stored: the run's task, method, seed, config, versions
and status, every proposal (``w`` and ``theta`` bytes, step, round, when it was proposed) and every
outcome (success, return, info, when it was told), the outcomes in the order they were told, and
what the run keeps in the meta table (``best``, ``end``, ``pattern``, ``robot``), under the run's
new id in the target (its next one); every time stamp is the source's.

A run's config is copied as it is: a run learned in a context names the runs it learned from
(``config["learned_from"]``) by their ids in the store it learned from, so copy it into that store.
"""

from __future__ import annotations

from corl.store.records import StoreError, _as_int
from corl.store.sqlite import RunStore

__all__ = ["copy_runs"]

_RUN_COLUMNS = "created, task, method, seed, config, versions, status"
_TRIAL_COLUMNS = "trial_index, step, round, w, w_shape, theta, theta_shape, proposed_at"
_OUTCOME_COLUMNS = "trial_index, success, return_, info, told_at"
_KEPT = ("best", "end", "pattern")  # meta keys "<name>:<run id>"; "robot:<run id>:<index>" besides


def _rows_of(source: RunStore, run_id: int) -> dict:
    """Every row of run ``run_id`` of ``source``, as stored."""
    run = source._read(f"SELECT {_RUN_COLUMNS} FROM runs WHERE id = ?", (run_id,))
    if not run:
        raise StoreError(f"store {source.path} has no run {run_id}; `corl runs` lists its runs")
    kept = source._read("SELECT key, value FROM meta WHERE key IN (" + ", ".join("?" * len(_KEPT)) + ")",
                        tuple(f"{name}:{run_id}" for name in _KEPT))
    prefix = f"robot:{run_id}:"
    holders = source._read("SELECT key, value FROM meta WHERE key >= ? AND key < ?", (prefix, prefix[:-1] + ";"))
    return {"run": run[0],
            "trials": source._read(f"SELECT {_TRIAL_COLUMNS} FROM trials WHERE run_id = ? ORDER BY trial_index",
                                   (run_id,)),
            "outcomes": source._read(f"SELECT {_OUTCOME_COLUMNS} FROM outcomes WHERE run_id = ? ORDER BY rowid",
                                     (run_id,)),
            "kept": [(key.split(":", 1)[0], value) for key, value in kept],
            "holders": [(key[len(prefix):], value) for key, value in holders]}


def copy_runs(target: RunStore, runs: list[tuple[RunStore, int]]) -> list[int]:
    """Copy each ``(source, run_id)`` of ``runs`` into ``target`` (a writer), in that order, in one
    transaction (all of them or, on any error, none); returns their ids in ``target``.

    Parameters
    ----------
    target : the store written to, opened for writing.
    runs : ``(source store, run id)`` pairs; a source may be read-only.
    """
    rows = [_rows_of(source, _as_int(run_id, what="run id")) for source, run_id in runs]
    names = ", ".join(f"{source.path}:{run_id}" for source, run_id in runs)
    ids = []
    with target._transaction(f"copy runs {names}") as db:
        for one in rows:
            cursor = db.execute(f"INSERT INTO runs ({_RUN_COLUMNS}) VALUES (?, ?, ?, ?, ?, ?, ?)", one["run"])
            new = int(cursor.lastrowid)
            db.executemany(f"INSERT INTO trials (run_id, {_TRIAL_COLUMNS}) VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?)",
                           [(new, *row) for row in one["trials"]])
            db.executemany(f"INSERT INTO outcomes (run_id, {_OUTCOME_COLUMNS}) VALUES (?, ?, ?, ?, ?, ?)",
                           [(new, *row) for row in one["outcomes"]])
            db.executemany("INSERT OR REPLACE INTO meta (key, value) VALUES (?, ?)",
                           [(f"{name}:{new}", value) for name, value in one["kept"]]
                           + [(f"robot:{new}:{index}", value) for index, value in one["holders"]])
            ids.append(new)
    return ids
