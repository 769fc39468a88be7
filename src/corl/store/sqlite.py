"""The SQLite run store (the file format is described in :mod:`corl.store`, the writer lock in
:mod:`corl.store.lock`)."""

from __future__ import annotations

import os
import sqlite3
from contextlib import contextmanager
from pathlib import Path
from typing import Any, Iterator, Mapping

from corl.errors import CorlError, InputError
from corl.problem import Outcome, Proposal
from corl.store.export import check_export_path, write_export
from corl.store.lock import WriterLock
from corl.store.machine import machine_info
from corl.store.meta import KeptByRun, note
from corl.store.records import (
    EmptyStoreError, RunInfo, RunStatus, StoreError, TrialRecord, _as_int, _decode_array, _encode_array, _json, _load_json, _now,
)
from corl.store.schema import _SCHEMA, _holds
from corl.store.wal import _fold_log, _log_holds_data, _sidecar, _wal_header, _writable
from corl.versions import library_versions

FORMAT_VERSION = 1  # the newest file format this corl reads and the one it writes
APPLICATION_ID = int.from_bytes(b"corl", "big")  # marks the SQLite file as a corl store
_BUSY_TIMEOUT_S = 5.0
_RESTORE_HINT = "restore it from a copy or start a new store with a different --store path"


class RunStore(KeptByRun):
    """Runs, their trials and outcomes in one SQLite file (see the docstring of :mod:`corl.store`).

    Parameters
    ----------
    path : the store file, e.g. ``runs/door.corl``; its folder must exist.
    create : create the file when it does not exist (writers only).
    readonly : open for reading only; never blocks and is never blocked by a writer.

    Notes
    -----
    Every method that writes has committed to disk when it returns. A RunStore is used from the
    thread that opened it; use it as a context manager or call :meth:`close`.
    """

    def __init__(self, path: str | os.PathLike, *, create: bool = True, readonly: bool = False) -> None:
        self.path = Path(path)
        self.readonly = bool(readonly)
        self._create = bool(create) and not self.readonly
        self._db: sqlite3.Connection | None = None
        self._lock: WriterLock | None = None
        self._ready = False  # a valid, initialised store: close() folds its log into the file
        self._check_location(must_exist=not self._create)
        try:
            if self.readonly:
                _fold_leftover_log(self.path)
            else:
                self._lock = WriterLock(self.path)
                self._lock.acquire(create=self._create)
                self._check_single_name()
            self._db = self._connect()
            self._check_or_initialise()
            self._ready = True
        except BaseException:
            self._discard_if_created()
            raise

    # -- opening -------------------------------------------------------------------------------
    def _check_location(self, *, must_exist: bool) -> None:
        folder = self.path.parent
        if not folder.is_dir():
            raise StoreError(
                f"the folder {folder} of store {self.path} does not exist; create it first or "
                "choose another --store path"
            )
        if self.path.exists() and not self.path.is_file():
            raise StoreError(f"store path {self.path} is not a file; choose another --store path")
        if must_exist and not self.path.exists():
            raise StoreError(f"no store at {self.path}; check the --store path (`corl runs` lists a store's runs)")

    def _check_single_name(self) -> None:
        """Refuse to write a file with several hard links: SQLite keeps one write-ahead log per name."""
        links = os.stat(self.path).st_nlink
        if links > 1:
            raise StoreError(
                f"store {self.path} has {links} names (hard links); SQLite keeps one write-ahead log per "
                "name, so a run written under two names can lose trials. Write through a copy "
                "(`cp`, or `sqlite3 STORE '.backup COPY'`) and remove the extra link"
            )

    def _connect(self) -> sqlite3.Connection:
        try:
            if self.readonly:
                uri = self.path.resolve().as_uri() + "?mode=ro"
                if not _writable(self.path):  # read-only media: no -shm can be created
                    if _log_holds_data(self.path):
                        raise StoreError(
                            f"store {self.path} sits in a read-only place with trials still in its write-ahead "
                            f"log {_sidecar(self.path, '-wal').name}; copy the store with its -wal file to a "
                            "writable folder and read it there (any corl command then folds the log in)"
                        )
                    uri += "&immutable=1"  # nothing can change it: read without locks or -shm
                db = sqlite3.connect(uri, uri=True, isolation_level=None, timeout=_BUSY_TIMEOUT_S)
            else:
                db = sqlite3.connect(str(self.path), isolation_level=None, timeout=_BUSY_TIMEOUT_S)
        except sqlite3.Error as exc:
            raise self._error_opening(exc) from None
        return db

    def _damaged(self, detail: object) -> StoreError:
        return StoreError(f"{self.path} is not a corl store or is damaged: {detail}; {_RESTORE_HINT}")

    def _error_opening(self, exc: sqlite3.Error) -> StoreError:
        if isinstance(exc, sqlite3.OperationalError):  # cannot open, busy, I/O: not the file's fault
            return StoreError(
                f"could not open store {self.path}: {exc}; check that the file is readable and, for "
                "writing, that its folder is writable"
            )
        return self._damaged(exc)

    def _check_or_initialise(self) -> None:
        db = self._db
        try:  # reading the header fails first on random bytes or a truncated file
            app_id = db.execute("PRAGMA application_id").fetchone()[0]
            header_format = db.execute("PRAGMA user_version").fetchone()[0]
            n_objects = db.execute("SELECT COUNT(*) FROM sqlite_master").fetchone()[0]
            if app_id == 0 and header_format == 0 and n_objects == 0:  # a new, empty file
                if self.readonly:
                    raise EmptyStoreError(f"{self.path} is empty, not a corl store; check the --store path")
                # writing (create, or resume): an empty file is a store whose creation was killed
                # before its first commit; nothing was in it, so it is initialised now
                self._initialise()
                return
            if app_id != APPLICATION_ID:
                raise self._damaged(f"it is an SQLite database of another program (application_id {app_id})")
            self._check_format(header_format)
            row = db.execute("SELECT value FROM meta WHERE key = 'format_version'").fetchone()
            if row is None or not str(row[0]).isdigit():
                raise self._damaged("its meta table has no format_version")
            self._check_format(int(row[0]))
            if int(row[0]) != header_format:
                raise self._damaged(f"format_version {row[0]} in its meta table but {header_format} in its header")
            problems = [line[0] for line in db.execute("PRAGMA quick_check")]  # every page readable
            if problems != ["ok"]:
                raise self._damaged("; ".join(problems[:3]))
            if not self.readonly:
                self._configure_writer()
        except sqlite3.Error as exc:
            raise self._error_opening(exc) from None

    def _check_format(self, found: int) -> None:
        if found > FORMAT_VERSION:
            raise StoreError(
                f"store {self.path} was written by a newer corl (format {found}, this corl reads up "
                f"to {FORMAT_VERSION}): upgrade corl"
            )
        if found < 1:
            raise self._damaged(f"unknown format {found}")

    def _configure_writer(self) -> None:
        db = self._db
        if db.execute("PRAGMA journal_mode = WAL").fetchone()[0] != "wal":
            raise StoreError(f"store {self.path} cannot use a write-ahead log; keep stores on a local disk")
        db.execute("PRAGMA synchronous = FULL")  # a commit has reached the disk before it returns
        db.execute("PRAGMA foreign_keys = ON")

    def _initialise(self) -> None:
        self._configure_writer()
        with self._transaction("create the store") as db:
            for statement in _SCHEMA:
                db.execute(statement)
            db.executemany(
                "INSERT INTO meta (key, value) VALUES (?, ?)",
                [("format_version", str(FORMAT_VERSION)), ("created", _now()),
                 ("created_by", f"corl {library_versions()['corl']}")],
            )
            db.execute(f"PRAGMA application_id = {APPLICATION_ID}")
            db.execute(f"PRAGMA user_version = {FORMAT_VERSION}")

    # -- plumbing ------------------------------------------------------------------------------
    @contextmanager
    def _transaction(self, what: str) -> Iterator[sqlite3.Connection]:
        """One write: ``BEGIN IMMEDIATE`` ... ``COMMIT``, rolled back on any error."""
        db = self._connection()
        if self.readonly:
            raise StoreError(f"cannot {what}: store {self.path} was opened read-only")
        try:
            db.execute("BEGIN IMMEDIATE")
            try:
                yield db
                db.execute("COMMIT")
            except BaseException:
                if db.in_transaction:
                    db.execute("ROLLBACK")
                raise
        except sqlite3.Error as exc:
            raise StoreError(f"could not {what} in store {self.path}: {exc}; nothing was written") from None

    def _connection(self) -> sqlite3.Connection:
        if self._db is None:
            raise StoreError(f"store {self.path} is closed; open a new RunStore")
        return self._db

    def _read(self, sql: str, params: tuple = ()) -> list[tuple]:
        try:
            return self._connection().execute(sql, params).fetchall()
        except sqlite3.Error as exc:
            raise StoreError(f"could not read store {self.path}: {exc}") from None

    def _run_status(self, db: sqlite3.Connection, run_id: int) -> RunStatus:
        row = db.execute("SELECT status FROM runs WHERE id = ?", (run_id,)).fetchone()
        if row is None:
            raise StoreError(f"store {self.path} has no run {run_id}; `corl runs` lists its runs")
        return RunStatus(row[0])

    def _require_running(self, db: sqlite3.Connection, run_id: int) -> None:
        if self._run_status(db, run_id) is not RunStatus.RUNNING:
            raise StoreError(
                f"run {run_id} is finished, so no trial is added to it; set its status to "
                "'running' first to extend it"
            )

    # -- runs ----------------------------------------------------------------------------------
    def create_run(
        self, *, task: str, method: str, seed: int | None, config: Mapping[str, Any],
        versions: Mapping[str, str] | None = None,
    ) -> int:
        """Start a run and return its id.

        ``versions`` defaults to :func:`library_versions` and :func:`corl.store.machine.machine_info`
        (processor, BLAS kernel) now.
        """
        for what, value in (("task", task), ("method", method)):
            if not isinstance(value, str) or not value:
                raise InputError(f"{what} must be a non-empty string, got {value!r}")
        seed = None if seed is None else _as_int(seed, what="seed")
        config_json = _json(dict(config), what="config")
        if versions is None:
            versions = {**library_versions(), **machine_info()}
        versions_json = _json(dict(versions), what="versions")
        with self._transaction(f"create a run of {method} on {task}") as db:
            cursor = db.execute(
                "INSERT INTO runs (created, task, method, seed, config, versions, status) "
                "VALUES (?, ?, ?, ?, ?, ?, ?)",
                (_now(), task, method, seed, config_json, versions_json, RunStatus.RUNNING.value),
            )
        return int(cursor.lastrowid)

    _RUNS_SQL = """SELECT r.id, r.created, r.task, r.method, r.seed, r.config, r.versions, r.status,
        (SELECT COUNT(*) FROM trials t WHERE t.run_id = r.id),
        (SELECT COUNT(*) FROM outcomes o WHERE o.run_id = r.id) FROM runs r"""

    @staticmethod
    def _run_info(row: tuple) -> RunInfo:
        rid, created, task, method, seed, config, versions, status, n_trials, n_told = row
        what = f"run {rid}"
        if not (isinstance(task, str) and isinstance(method, str)):
            raise StoreError(f"the task or method of {what} is not text; the store is damaged")
        if seed is not None and (not isinstance(seed, int) or seed < 0):
            raise StoreError(f"the seed of {what} is {seed!r}, not a non-negative integer; the store is damaged")
        try:
            status = RunStatus(status)
        except ValueError:
            raise StoreError(f"the status of {what} is {status!r}; the store is damaged") from None
        return RunInfo(rid, str(created), task, method, seed,
                       _load_json(config, what=f"the configuration of {what}", kind=dict),
                       _load_json(versions, what=f"the versions of {what}", kind=dict), status, n_trials, n_told)

    def runs(self) -> list[RunInfo]:
        """Every run, oldest first."""
        return [self._run_info(row) for row in self._read(self._RUNS_SQL + " ORDER BY r.id")]

    def run(self, run_id: int) -> RunInfo:
        """The run with id ``run_id``; raises :class:`StoreError` when there is none."""
        rows = self._read(self._RUNS_SQL + " WHERE r.id = ?", (_as_int(run_id, what="run id"),))
        if not rows:
            raise StoreError(f"store {self.path} has no run {run_id}; `corl runs` lists its runs")
        return self._run_info(rows[0])

    def latest_run(self) -> RunInfo | None:
        """The most recently created run, or None for an empty store."""
        rows = self._read(self._RUNS_SQL + " ORDER BY r.id DESC LIMIT 1")
        return self._run_info(rows[0]) if rows else None

    def set_status(self, run_id: int, status: RunStatus | str) -> None:
        """Mark a run "running" or "finished"."""
        try:
            status = RunStatus(status)
        except ValueError:
            choices = ", ".join(s.value for s in RunStatus)
            raise InputError(f"status must be one of {choices}, got {status!r}") from None
        run_id = _as_int(run_id, what="run id")
        with self._transaction(f"mark run {run_id} {status.value}") as db:
            self._run_status(db, run_id)
            db.execute("UPDATE runs SET status = ? WHERE id = ?", (status.value, run_id))

    # -- trials --------------------------------------------------------------------------------
    def add_proposal(self, run_id: int, proposal: Proposal) -> None:
        """Store a proposal before it is executed.

        The index must be the run's next one, and fewer trials pending than the run has robots
        (``config["robots"]``, 1 by default: the previous trial must be told). Storing the same
        trial again with identical content (bit for bit) does nothing, so a loop that re-asks a
        pending trial after a crash can store it again; different content raises StoreError.
        """
        if not isinstance(proposal, Proposal):
            raise InputError(f"add_proposal needs a Proposal, got {type(proposal).__name__}")
        run_id = _as_int(run_id, what="run id")
        index = _as_int(proposal.index, what="proposal index", minimum=0)
        w, w_shape = _encode_array(proposal.w, what="w")
        theta, theta_shape = _encode_array(proposal.theta, what="theta")
        content = (str(proposal.step), _as_int(proposal.round, what="round"), w, w_shape, theta, theta_shape)
        with self._transaction(f"store trial {index} of run {run_id}") as db:
            self._require_running(db, run_id)
            stored = db.execute(
                "SELECT step, round, w, w_shape, theta, theta_shape FROM trials "
                "WHERE run_id = ? AND trial_index = ?", (run_id, index),
            ).fetchone()
            if stored is not None:
                if tuple(stored) == content:
                    return  # the same trial asked again
                names = ("step", "round", "w", "w", "theta", "theta")
                changed = ", ".join(dict.fromkeys(n for n, a, b in zip(names, stored, content) if a != b))
                raise StoreError(
                    f"run {run_id} already holds a different trial {index} ({changed} differ); a stored "
                    "trial is never replaced. Resume the run with replay() from a fresh learner, or "
                    "start a new run"
                )
            last = db.execute("SELECT MAX(trial_index) FROM trials WHERE run_id = ?", (run_id,)).fetchone()[0]
            expected = 0 if last is None else last + 1
            if index != expected:
                raise StoreError(f"run {run_id} expects trial {expected} next, got a proposal for trial {index}")
            self.check_room(db, run_id, last, index)
            db.execute(
                "INSERT INTO trials (run_id, trial_index, step, round, w, w_shape, theta, theta_shape, "
                "proposed_at) VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?)", (run_id, index, *content, _now()),
            )
            note(db, run_id, "a")

    def add_outcome(self, run_id: int, index: int, outcome: Outcome) -> None:
        """Store the outcome of trial ``index``; a trial is told exactly once."""
        if not isinstance(outcome, Outcome):
            raise InputError(f"add_outcome needs an Outcome, got {type(outcome).__name__}")
        run_id = _as_int(run_id, what="run id")
        index = _as_int(index, what="trial index", minimum=0)
        info = _json(dict(outcome.info), what="outcome.info")
        with self._transaction(f"store the outcome of trial {index} of run {run_id}") as db:
            self._require_running(db, run_id)
            if not _holds(db, "trials", run_id, index):
                raise StoreError(f"run {run_id} has no trial {index}; store its proposal (add_proposal) before its outcome")
            if _holds(db, "outcomes", run_id, index):
                raise StoreError(f"trial {index} of run {run_id} already has an outcome; a trial is told once")
            db.execute(
                "INSERT INTO outcomes (run_id, trial_index, success, return_, info, told_at) "
                "VALUES (?, ?, ?, ?, ?, ?)",
                (run_id, index, int(outcome.success), outcome.return_, info, _now()),
            )
            note(db, run_id, "t")

    _TRIALS_SQL = """SELECT t.trial_index, t.step, t.round, t.w, t.w_shape, t.theta, t.theta_shape,
        t.proposed_at, o.success, o.return_, o.info, o.told_at
        FROM trials t LEFT JOIN outcomes o ON o.run_id = t.run_id AND o.trial_index = t.trial_index
        WHERE t.run_id = ?"""

    def _records(self, run_id: int, sql: str) -> list[TrialRecord]:
        run_id = self.run(run_id).id  # raises for an unknown run
        records = []
        for row in self._read(sql, (run_id,)):
            index, step, rnd, w, w_shape, theta, theta_shape, proposed_at, success, ret, info, told_at = row
            what = f"trial {index} of run {run_id}"
            w = _decode_array(w, w_shape, what=f"w of {what}")
            theta = _decode_array(theta, theta_shape, what=f"theta of {what}")
            proposal = Proposal(index, w, theta, step, rnd)
            outcome = None if told_at is None else self._outcome(success, ret, info, what)
            records.append(TrialRecord(proposal, outcome, proposed_at, told_at))
        return records

    @staticmethod
    def _outcome(success: Any, ret: Any, info: Any, what: str) -> Outcome:
        info = _load_json(info, what=f"the outcome information of {what}", kind=dict)
        try:
            return Outcome(bool(success), ret, info)
        except CorlError as exc:
            raise StoreError(f"the outcome of {what} is not valid ({exc}); the store is damaged") from None

    def trials(self, run_id: int) -> list[TrialRecord]:
        """Every stored trial of a run in index order; ``outcome`` is None while pending."""
        return self._records(run_id, self._TRIALS_SQL + " ORDER BY t.trial_index")

    def pending(self, run_id: int) -> TrialRecord | None:
        """The latest trial proposed and not told yet, if any (with one robot, only the last trial can be;
        with several, :meth:`pending_trials` lists them all)."""
        sql = self._TRIALS_SQL + " AND o.run_id IS NULL ORDER BY t.trial_index DESC LIMIT 1"
        records = self._records(run_id, sql)
        return records[0] if records else None

    # -- export --------------------------------------------------------------------------------
    def export(self, run_id: int | list[int], path: str | os.PathLike) -> tuple[Path, Path]:
        """Write a run's trials (``run_id`` a list: those runs' trials, a ``run`` column first) as a table
        (``.csv``, or ``.parquet`` when pyarrow is installed), the w vectors beside it in ``<name>.w.npz``.

        One row per trial: [run,] index, step, round, [context_0..context_{k-1}: the run's scene,] theta_0..,
        success (1/0), return, proposed_at, told_at (:func:`corl.store.export.write_export`). Returns the
        paths of the table and of the ``.npz`` file.
        """
        path = check_export_path(path)
        several = not isinstance(run_id, int)
        ids = list(run_id) if several else [run_id]
        return write_export([(self.run(i), self.trials(i)) for i in ids], path, several=several)

    # -- life cycle ----------------------------------------------------------------------------
    def close(self) -> None:
        """Close the file and release the writer lock; closing twice is harmless.

        A writer first folds its write-ahead log into the store file (checkpoint, then back to a
        rollback journal), so a closed store is one file that can be copied alone.
        """
        if self._db is not None:
            if self._ready and not self.readonly:
                _fold_log(self._db)
            self._db.close()
            self._db = None
        if self._lock is not None:
            self._lock.release()
            self._lock = None

    def _discard_if_created(self) -> None:
        """After a refused open: close, and remove the store file if this open created it."""
        created = self._lock is not None and self._lock.created
        if self._db is not None:
            self._db.close()
            self._db = None
        if created:  # still locked: nobody else can have opened it meanwhile
            for name in ("", "-wal", "-shm", "-journal"):
                Path(str(self.path) + name).unlink(missing_ok=True)
        self.close()

    def __enter__(self) -> RunStore:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()

    def __repr__(self) -> str:
        mode = "read-only" if self.readonly else "writer"
        state = "closed" if self._db is None else "open"
        return f"RunStore({str(self.path)!r}, {mode}, {state})"


# -- the store at rest: one file (the log's helpers: corl.store.wal) -----------------------------------
def _fold_leftover_log(path: Path) -> None:
    """Before reading: fold the log a killed writer left behind, when no one writes the store now."""
    if not ((_log_holds_data(path) or _wal_header(path)) and _writable(path)):
        return
    try:
        RunStore(path, create=False).close()
    except StoreError:
        pass  # a live writer (it folds the log itself), a damaged file (the read says so), ...
