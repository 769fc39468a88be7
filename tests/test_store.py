"""Tests of the run store: exact round trips, refusals that leave the store as it was, damaged and
foreign files, one writer at a time, exact resume with replay, and SIGKILL at random moments."""

from __future__ import annotations

import csv
import os
import shutil
import signal
import sqlite3
import subprocess
import sys
import textwrap
import time

import numpy as np
import pytest

from corl.errors import InputError, StateError
from corl.problem import Outcome, Proposal
from corl.store import FORMAT_VERSION, RunStatus, RunStore, StoreError, replay
from corl.store.machine import machine_info
from corl.versions import library_versions, version_differences


# -- helpers ---------------------------------------------------------------------------------------
class FakeLearner:
    """Deterministic given its seed; each w depends on the last return told (gain * R)."""

    def __init__(self, seed: int, *, n: int = 6, m: int = 2, gain: float = 1.0) -> None:
        self._rng = np.random.default_rng(seed)
        self.n, self.m, self.gain = n, m, gain
        self._pending: Proposal | None = None
        self.told: list[Outcome] = []

    def ask(self) -> Proposal:
        if self._pending is None:
            k = len(self.told)
            last = self.told[-1].return_ if self.told and self.told[-1].return_ is not None else 0.0
            w = self._rng.normal(size=self.n) + self.gain * last
            theta = self._rng.uniform(-1.0, 1.0, size=self.m)
            self._pending = Proposal(k, w, theta, "reinforcement" if k % 2 else "optimization", k // 3)
        return self._pending

    def tell(self, outcome: Outcome) -> None:
        if self._pending is None:
            raise StateError("tell without ask")
        self.told.append(outcome)
        self._pending = None


def rollout(p: Proposal) -> Outcome:
    success = bool(p.theta[0] > -0.5)
    return Outcome(success, float(-np.sum(p.w**2)) / p.w.size if success else None, {"k": p.index})


def run_trials(learner, store: RunStore, run_id: int, count: int) -> None:
    """The robot loop: ask, store, execute, store, tell."""
    for _ in range(count):
        p = learner.ask()
        store.add_proposal(run_id, p)
        outcome = rollout(p)
        store.add_outcome(run_id, p.index, outcome)
        learner.tell(outcome)


def new_run(store: RunStore, **overrides) -> int:
    # the versions of this interpreter (the resume tests read a version change as the likely cause)
    settings = dict(task="synthetic", method="corl", seed=3, config={"eps_theta": 1e-3}, versions={"numpy": np.__version__})
    return store.create_run(**{**settings, **overrides})


def snapshot(store: RunStore, run_id: int) -> list[tuple]:
    """Every stored field of every trial, arrays as bytes, for before/after comparisons."""
    rows = []
    for r in store.trials(run_id):
        p, o = r.proposal, r.outcome
        told = None if o is None else (o.success, o.return_, dict(o.info))
        rows.append((p.index, p.step, p.round, p.w.tobytes(), p.theta.tobytes(), told, r.proposed_at, r.told_at))
    return rows


@pytest.fixture
def store_path(tmp_path):
    return tmp_path / "runs.corl"


@pytest.fixture
def filled_store(store_path):
    """A closed store with one run of 5 told trials (n=300, so the file spans many pages)."""
    with RunStore(store_path) as store:
        run_trials(FakeLearner(0, n=300), store, new_run(store), 5)
    return store_path


# -- round trips -----------------------------------------------------------------------------------
def test_round_trip_is_bit_exact(store_path):
    w = np.array([-0.0, 5e-324, np.nan, np.inf, -np.inf, 1e308, 0.1 + 0.2, np.nextafter(1.0, 2.0)])
    theta = np.array([np.pi, -1.0 / 3.0])
    with RunStore(store_path) as store:
        run = new_run(store, seed=2**40, config={"knots": 17, "preset": "paper"})
        store.add_proposal(run, Proposal(0, w, theta, "demonstration", 0))
        store.add_outcome(run, 0, Outcome(True, 1.0 / 7.0, {"angle": 0.3, "forces": [1.5, 2.5]}))
    with RunStore(store_path, readonly=True) as store:
        (record,) = store.trials(run)
        info = store.run(run)
    assert record.proposal.w.tobytes() == w.tobytes()
    assert record.proposal.theta.tobytes() == theta.tobytes()
    assert record.proposal.w.dtype == np.float64 and record.proposal.w.flags.writeable
    assert (record.index, record.proposal.step, record.proposal.round) == (0, "demonstration", 0)
    assert record.outcome.success is True and record.outcome.return_ == 1.0 / 7.0
    assert dict(record.outcome.info) == {"angle": 0.3, "forces": [1.5, 2.5]}
    assert (info.seed, info.config, info.versions) == (2**40, {"knots": 17, "preset": "paper"}, {"numpy": np.__version__})
    assert (info.status, info.n_trials, info.n_told) == (RunStatus.RUNNING, 1, 1)


def test_failed_outcome_without_return_reads_back_as_none(store_path):
    with RunStore(store_path) as store:
        run = new_run(store)
        store.add_proposal(run, Proposal(0, np.ones(3), np.zeros(1), "phase"))
        store.add_outcome(run, 0, Outcome(False))
        outcome = store.trials(run)[0].outcome
    assert outcome.success is False and outcome.return_ is None


def test_versions_default_to_the_installed_libraries_and_differences_are_listed(store_path):
    versions = library_versions()
    assert {"python", "corl", "numpy", "scipy", "cma", "joblib", "platform"} <= set(versions)
    assert versions["numpy"] == np.__version__
    with RunStore(store_path) as store:
        stored = store.run(store.create_run(task="door", method="cma", seed=None, config={})).versions
    assert stored == {**versions, **machine_info()} and "cpu" in stored
    changed = version_differences({"numpy": "2.3.5", "scipy": "1.16.3"}, {"numpy": "2.4.0", "scipy": "1.16.3"})
    assert changed == ["numpy 2.3.5 -> 2.4.0"]


@pytest.mark.parametrize("reopen", [False, True])
def test_writer_commits_durably(store_path, reopen):
    RunStore(store_path).close()
    with RunStore(store_path) if reopen else RunStore(store_path.with_name("other.corl")) as store:
        db = store._db  # the settings durability rests on
        assert db.execute("PRAGMA journal_mode").fetchone()[0] == "wal"
        assert db.execute("PRAGMA synchronous").fetchone()[0] == 2  # FULL: fsync on every commit
        assert db.execute("PRAGMA foreign_keys").fetchone()[0] == 1  # no outcome without its proposal


# -- refusals leave the store as it was ------------------------------------------------------------
def test_second_outcome_is_refused_and_changes_nothing(store_path):
    with RunStore(store_path) as store:
        run = new_run(store)
        run_trials(FakeLearner(1), store, run, 3)
        before = snapshot(store, run)
        with pytest.raises(StoreError, match="trial 1 of run 1 already has an outcome; a trial is told once"):
            store.add_outcome(run, 1, Outcome(True, 99.0))
        assert snapshot(store, run) == before


def test_outcome_for_unknown_trial_or_run_is_refused(store_path):
    with RunStore(store_path) as store:
        run = new_run(store)
        run_trials(FakeLearner(1), store, run, 2)
        before = snapshot(store, run)
        with pytest.raises(StoreError, match="run 1 has no trial 5; store its proposal"):
            store.add_outcome(run, 5, Outcome(False))
        with pytest.raises(StoreError, match="has no run 9"):
            store.add_outcome(9, 0, Outcome(False))
        assert snapshot(store, run) == before


def test_proposals_are_stored_once_in_order(store_path):
    with RunStore(store_path) as store:
        run = new_run(store)
        learner = FakeLearner(2)
        run_trials(learner, store, run, 2)
        p = learner.ask()
        store.add_proposal(run, p)
        store.add_proposal(run, Proposal(p.index, p.w.copy(), p.theta.copy(), p.step, p.round))  # re-ask: no-op
        assert len(store.trials(run)) == 3 and store.pending(run).proposal.w.tobytes() == p.w.tobytes()
        nudged = p.w.copy()
        nudged[0] = np.nextafter(nudged[0], np.inf)
        with pytest.raises(StoreError, match="already holds a different trial 2 \\(w differ"):
            store.add_proposal(run, Proposal(2, nudged, p.theta, p.step, p.round))
        with pytest.raises(StoreError, match="trial 2 of run 1 is still pending"):
            store.add_proposal(run, Proposal(3, p.w, p.theta, p.step, p.round))
        store.add_outcome(run, 2, Outcome(False))
        with pytest.raises(StoreError, match="expects trial 3 next, got a proposal for trial 5"):
            store.add_proposal(run, Proposal(5, p.w, p.theta, p.step, p.round))
        assert store.pending(run) is None and [r.index for r in store.trials(run)] == [0, 1, 2]


def test_run_status_and_listing(store_path):
    with RunStore(store_path) as store:
        assert store.runs() == [] and store.latest_run() is None
        first, second = new_run(store), new_run(store, method="pibu")
        store.set_status(first, "finished")
        assert [(r.id, r.status) for r in store.runs()] == [(first, RunStatus.FINISHED), (second, RunStatus.RUNNING)]
        assert store.latest_run().method == "pibu"
        with pytest.raises(StoreError, match="run 1 is finished"):
            store.add_proposal(first, Proposal(0, np.ones(2), np.ones(1), "search"))
        with pytest.raises(InputError, match="status must be one of running, finished"):
            store.set_status(first, "paused")
        with pytest.raises(StoreError, match="has no run 7"):
            store.run(7)


# -- damaged, foreign, newer and missing files -----------------------------------------------------
def assert_refused_untouched(path, match, **kwargs):
    before = path.read_bytes()
    with pytest.raises(StoreError, match=match):
        RunStore(path, **kwargs)
    assert path.read_bytes() == before


DAMAGED = (r"is not a corl store or is damaged: .+; "
           r"restore it from a copy or start a new store with a different --store path")


@pytest.mark.parametrize("readonly", [False, True])
def test_random_bytes_are_refused_and_left_untouched(store_path, readonly):
    store_path.write_bytes(np.random.default_rng(5).bytes(8192))
    assert_refused_untouched(store_path, DAMAGED, readonly=readonly)


@pytest.mark.parametrize("readonly", [False, True])
def test_truncated_store_is_refused_and_left_untouched(filled_store, tmp_path, readonly):
    copy = tmp_path / "copy.corl"
    shutil.copyfile(filled_store, copy)
    os.truncate(copy, copy.stat().st_size // 2)
    assert_refused_untouched(copy, DAMAGED, readonly=readonly)
    with RunStore(filled_store, readonly=True) as store:  # the original is intact
        assert len(store.trials(1)) == 5


def test_other_sqlite_database_is_refused(store_path):
    with sqlite3.connect(store_path) as db:
        db.execute("CREATE TABLE notes (text TEXT)")
    db.close()
    assert_refused_untouched(store_path, "SQLite database of another program")


def test_newer_format_is_refused(filled_store):
    db = sqlite3.connect(filled_store, isolation_level=None)
    db.execute(f"PRAGMA user_version = {FORMAT_VERSION + 1}")
    db.execute("UPDATE meta SET value = ? WHERE key = 'format_version'", (str(FORMAT_VERSION + 1),))
    db.close()
    newer = (rf"written by a newer corl \(format {FORMAT_VERSION + 1}, "
             rf"this corl reads up to {FORMAT_VERSION}\): upgrade corl")
    assert_refused_untouched(filled_store, newer)
    assert_refused_untouched(filled_store, newer, readonly=True)


def test_missing_folder_or_file_is_refused(tmp_path):
    with pytest.raises(StoreError, match="does not exist; create it first"):
        RunStore(tmp_path / "no" / "such" / "runs.corl")
    with pytest.raises(StoreError, match="no store at"):
        RunStore(tmp_path / "absent.corl", create=False)
    with pytest.raises(StoreError, match="no store at"):
        RunStore(tmp_path / "absent.corl", readonly=True)
    assert not (tmp_path / "absent.corl").exists()


# -- one writer, many readers ----------------------------------------------------------------------
def test_second_writer_is_refused_until_the_first_closes(store_path):
    first = RunStore(store_path)
    run = new_run(first)
    start = time.monotonic()
    with pytest.raises(StoreError, match=rf"already open for writing by process {os.getpid()} "):
        RunStore(store_path)
    assert time.monotonic() - start < 1.0  # refused at once, not after a timeout
    first.close()
    with RunStore(store_path) as second:
        assert second.run(run).task == "synthetic"


def test_reader_works_beside_a_writer(store_path):
    with RunStore(store_path) as writer:
        run = new_run(writer)
        learner = FakeLearner(4)
        run_trials(learner, writer, run, 2)
        with RunStore(store_path, readonly=True) as reader:
            assert [r.index for r in reader.trials(run)] == [0, 1]
            writer.add_proposal(run, learner.ask())
            assert reader.pending(run).index == 2  # sees each commit
            with pytest.raises(StoreError, match="opened read-only"):
                reader.add_outcome(run, 2, Outcome(False))
        assert writer.pending(run).index == 2


HOLD_WRITER = textwrap.dedent(
    """
    import sys, time
    import numpy as np
    from corl.problem import Proposal
    from corl.store import RunStore
    store = RunStore(sys.argv[1])
    run = store.create_run(task="door", method="corl", seed=0, config={}, versions={})
    store.add_proposal(run, Proposal(0, np.arange(4.0), np.ones(2), "demonstration"))
    print("ready", flush=True)
    time.sleep(60)
    """
)


def test_lock_of_a_killed_writer_does_not_block_resume(store_path):
    child = subprocess.Popen([sys.executable, "-c", HOLD_WRITER, str(store_path)], stdout=subprocess.PIPE, text=True)
    try:
        assert child.stdout.readline().strip() == "ready"
        with pytest.raises(StoreError, match=rf"already open for writing by process {child.pid} "):
            RunStore(store_path)
    finally:
        child.send_signal(signal.SIGKILL)
        child.wait()
    with RunStore(store_path) as store:
        assert store.pending(1).proposal.w.tolist() == [0.0, 1.0, 2.0, 3.0]


# -- export ----------------------------------------------------------------------------------------
def test_export_csv_and_npz(store_path, tmp_path):
    with RunStore(store_path) as store:
        run = new_run(store)
        learner = FakeLearner(0, n=5, m=3)
        run_trials(learner, store, run, 4)
        store.add_proposal(run, learner.ask())
        records = store.trials(run)
        table, npz = store.export(run, tmp_path / "run1.csv")
        with pytest.raises(InputError, match=r"\.csv or \.parquet"):
            store.export(run, tmp_path / "run1.xlsx")
    with open(table, newline="") as f:
        rows = list(csv.DictReader(f))
    assert list(rows[0]) == ["index", "step", "round", "theta_0", "theta_1", "theta_2", "success", "return",
                             "proposed_at", "told_at"]
    assert len(rows) == 5
    for row, record in zip(rows, records):
        p, o = record.proposal, record.outcome
        assert (int(row["index"]), row["step"], int(row["round"])) == (p.index, p.step, p.round)
        assert [float(row[f"theta_{j}"]) for j in range(3)] == p.theta.tolist()  # exact digits
        assert row["proposed_at"] == record.proposed_at
        if o is None:
            assert row["success"] == row["return"] == row["told_at"] == ""
        else:
            assert row["success"] == str(int(o.success))
            assert row["return"] == ("" if o.return_ is None else repr(o.return_))
    assert {row["success"] for row in rows[:4]} == {"0", "1"}  # both kinds occur in this run
    with np.load(npz, allow_pickle=False) as data:
        assert data["index"].tolist() == [0, 1, 2, 3, 4]
        assert np.array_equal(data["w"], np.stack([r.proposal.w for r in records]))


def test_parquet_export_without_pyarrow_says_what_to_install(store_path, tmp_path):
    try:
        import pyarrow  # noqa: F401
    except ImportError:
        pass
    else:
        pytest.skip("pyarrow is installed")
    with RunStore(store_path) as store:
        run = new_run(store)
        with pytest.raises(StoreError, match="needs pyarrow"):
            store.export(run, tmp_path / "run.parquet")
    assert not (tmp_path / "run.parquet").exists()


# -- exact resume ----------------------------------------------------------------------------------
def test_replay_resumes_exactly_with_a_pending_last_trial(store_path):
    original = FakeLearner(7)
    with RunStore(store_path) as store:
        run = new_run(store)
        run_trials(original, store, run, 4)
        store.add_proposal(run, original.ask())  # trial 4 asked, then the process "dies"
    resumed = FakeLearner(7)
    with RunStore(store_path) as store:
        assert replay(resumed, store, run) == 4
        assert [o.return_ for o in resumed.told] == [o.return_ for o in original.told]
        pending = resumed.ask()
        assert pending.index == 4 and pending.w.tobytes() == store.pending(run).proposal.w.tobytes()
        store.add_proposal(run, pending)  # the loop stores it again: a no-op
        outcome = rollout(pending)
        store.add_outcome(run, 4, outcome)
        resumed.tell(outcome)
        original.tell(outcome)
        run_trials(resumed, store, run, 3)
    for _ in range(3):  # the uninterrupted learner proposes the same continuation
        p = original.ask()
        original.tell(rollout(p))
    with RunStore(store_path, readonly=True) as store:
        stored = store.trials(run)
    assert [r.index for r in stored] == list(range(8))
    assert stored[-1].proposal.w.tobytes() == p.w.tobytes()


def test_replay_reports_where_the_run_stops_matching(store_path):
    with RunStore(store_path) as store:
        run = new_run(store)
        run_trials(FakeLearner(8, gain=1.0), store, run, 3)
        with pytest.raises(StoreError, match="does not propose the stored trial 0: w differs by .* the likely cause "
                                             "is the code or the configuration"):
            replay(FakeLearner(9), store, run)
        # same seed, but w depends on the told return differently: the first trial still matches
        with pytest.raises(StoreError, match="trial 1: w differs"):
            replay(FakeLearner(8, gain=2.0), store, run)
        with pytest.raises(StoreError, match="trial 0: w has shape \\(4,\\), the store holds \\(6,\\)"):
            replay(FakeLearner(8, n=4), store, run)
        older = new_run(store, versions={"numpy": "1.26.4"})
        run_trials(FakeLearner(8), store, older, 1)
        with pytest.raises(StoreError, match=f"Likely cause: this machine's software .*numpy 1.26.4 -> {np.__version__}"):
            replay(FakeLearner(9), store, older)


# -- crashes ---------------------------------------------------------------------------------------
WRITE_FOREVER = textwrap.dedent(
    """
    import sys
    import numpy as np
    from corl.problem import Outcome, Proposal
    from corl.store import RunStore
    store = RunStore(sys.argv[1])
    run = store.latest_run().id if store.latest_run() else store.create_run(
        task="door", method="corl", seed=0, config={}, versions={})
    k = len(store.trials(run))
    if store.pending(run) is not None:
        k -= 1
    print("ready", flush=True)
    while True:
        rng = np.random.default_rng(k)
        store.add_proposal(run, Proposal(k, rng.normal(size=1200), rng.normal(size=2), "reinforcement", k // 10))
        store.add_outcome(run, k, Outcome(bool(k % 3), float(k) if k % 3 else None, {"k": k}))
        k += 1
    """
)


def test_sigkill_at_random_moments_leaves_a_consistent_prefix(store_path):
    moments = np.random.default_rng(11).uniform(0.0, 0.1, size=6)
    sizes = []
    for moment in moments:
        child = subprocess.Popen([sys.executable, "-c", WRITE_FOREVER, str(store_path)],
                                 stdout=subprocess.PIPE, text=True)
        try:
            assert child.stdout.readline().strip() == "ready"
            time.sleep(moment)
        finally:
            child.send_signal(signal.SIGKILL)
            child.wait()
        with RunStore(store_path, readonly=True) as store:  # `corl status` right after the crash
            seen = snapshot(store, 1)
        with RunStore(store_path) as store:  # opens, and the killed writer's lock is gone
            records = store.trials(1)
            assert snapshot(store, 1) == seen
        sizes.append(len(records))
        assert [r.index for r in records] == list(range(len(records)))
        assert all(r.outcome is not None for r in records[:-1])
        for r in records:
            rng = np.random.default_rng(r.index)
            assert r.proposal.w.tobytes() == rng.normal(size=1200).tobytes()
            assert r.proposal.theta.tobytes() == rng.normal(size=2).tobytes()
            if r.outcome is not None:
                assert (r.outcome.success, r.outcome.info) == (bool(r.index % 3), {"k": r.index})
    assert sizes == sorted(sizes) and sizes[-1] > 0  # nothing lost between kills
    with sqlite3.connect(f"file:{store_path}?mode=ro", uri=True) as db:
        assert db.execute("PRAGMA integrity_check").fetchall() == [("ok",)]
