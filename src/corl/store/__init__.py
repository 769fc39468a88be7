"""The run store: every trial of a run, committed to SQLite before the learning loop moves on.

On a real robot a trial costs minutes, so the store never loses, repeats or corrupts one:

- every write (one proposal, one outcome, one run) is one transaction, ``BEGIN IMMEDIATE ...
  COMMIT``, in WAL mode with ``synchronous=FULL``: a process killed at any moment leaves the old
  or the new state, never half a trial, and a call that returned has reached the disk;
- one writer at a time: a writing :class:`RunStore` holds an exclusive ``flock`` on the store file
  itself for its whole life (:mod:`corl.store.lock`), so every name of the file (hard links,
  symlinks) meets the same lock, and a file with several hard links is not written at all (SQLite
  keeps one write-ahead log per name). The kernel releases the lock when the process exits or is
  killed, so a crashed run never blocks its own resume. Readers (``readonly=True``) open at any
  time and see the last committed state;
- one file at rest: closing a writer checkpoints its write-ahead log into the file and returns to a
  rollback journal, and a reader first folds in the log a killed writer left behind (when no one
  writes the store now), so after any command ``run.corl`` alone holds every trial and can be
  copied alone. In a read-only place (a read-only folder, mount or file) a store is read with
  SQLite's ``immutable`` open, which needs no ``-shm`` file;
- arrays are stored as raw little-endian float64 bytes beside their shape (never pickled), so they
  come back bit for bit;
- :func:`replay` resumes a run exactly: a fresh deterministic learner is asked again for every
  stored trial, must propose the same trial (bit for bit, or within :data:`RESUME_RTOL` when
  another CPU's arithmetic differs in the last bits), continues from the stored proposal (what the
  robot executed) and is told every stored outcome. A run ended where the task's code raised
  (``corl run --resume --end-at-error``, :meth:`RunStore.set_end`) replays up to that error.

A run's trials form a prefix: indices 0, 1, ..., d-1 without gaps, every outcome belongs to a
stored proposal, and only the last trial may be pending (asked, not yet told); a run with K robots
(``config["robots"] = K``) may have up to K trials pending, told in any order, and keeps the order of
its asks and tells (:mod:`corl.store.meta`) so that replay meets every trial as it was proposed.

Schema (format 1; ``PRAGMA user_version`` and ``meta.format_version`` hold the format)
------------------------------------------------------------------------------------------
meta(key, value)                  format_version, created, created_by; best:<run>, end:<run> (JSON);
                                  pattern:<run> (K robots: letters a, t, w); robot:<run>:<index>
                                  (corl serve --robots K: the robot a trial was handed to)
runs(id, created, task, method, seed, config, versions, status)    config, versions: JSON
trials(run_id, trial_index, step, round, w, w_shape, theta, theta_shape, proposed_at)
outcomes(run_id, trial_index, success, return_, info, told_at)     return_ NULL when unobserved
``w``, ``theta``: float64 little-endian bytes; ``*_shape``: JSON list; times: ISO 8601 UTC.
"""

from corl.store.records import EmptyStoreError, RunInfo, RunStatus, StoreError, TrialRecord
from corl.store.resume import RESUME_RTOL, AskTellLearner, replay
from corl.store.sqlite import APPLICATION_ID, FORMAT_VERSION, RunStore

__all__ = ["FORMAT_VERSION", "RESUME_RTOL", "RunInfo", "RunStatus", "RunStore", "StoreError", "TrialRecord", "replay",
           "latest_run"]


def latest_run(path) -> RunInfo | None:
    """The latest run of the store at ``path``, read without opening it for writing (a command that may
    still be refused leaves the file's bytes as they were); None without a store or a run in it."""
    from pathlib import Path

    if not Path(path).is_file():
        return None
    try:
        with RunStore(path, readonly=True) as db:
            return db.latest_run()
    except EmptyStoreError:  # created, then killed before its first commit: no run yet
        return None
