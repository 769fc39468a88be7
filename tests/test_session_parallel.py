"""K robots in the run store: K pending trials recorded, a crash with K out loses none, resume ends as
an uninterrupted run with the same pending pattern (corl.store.meta, corl.session.StoredRun)."""

import os
import signal
import subprocess
import sys
import textwrap

import numpy as np
import pytest

from corl.errors import StateError
from corl.problem import Outcome, Proposal
from corl.session import StoredRun
from corl.store import RunStore, StoreError
from corl.tasks.registry import load_task


FAST = {"rollout_every_step": False}  # step 1 rolls out its converged motion only: ~40 trials


@pytest.fixture(scope="module")
def task():
    return load_task("synthetic", seed=0)


def trial(i):
    return Proposal(i, np.array([0.1 * i, 1.0]), np.array([0.1 * i]), "reinforcement", 0)


def test_the_store_holds_up_to_k_pending_trials_told_in_any_order(tmp_path):
    with RunStore(tmp_path / "k.corl") as db:
        run = db.create_run(task="t", method="CORL", seed=0, config={"robots": 3})
        for i in range(3):
            db.add_proposal(run, trial(i))
        with pytest.raises(StoreError, match="3 trials pending, one per robot"):
            db.add_proposal(run, trial(3))
        db.add_outcome(run, 2, Outcome(True, 1.0))
        db.add_proposal(run, trial(3))
        db.add_outcome(run, 0, Outcome(False, None))
        assert [r.index for r in db.pending_trials(run)] == [1, 3]
        assert db.told_order(run) == [2, 0]
        db.note_wait(run)
        db.note_wait(run)  # a second ask with no tell between finds the learner as the first did
        assert db.pattern(run) == "aaatatw"
        one = db.create_run(task="t", method="CORL", seed=0, config={})
        db.add_proposal(one, trial(0))
        with pytest.raises(StoreError, match="trial 0 of run 2 is still pending"):
            db.add_proposal(one, trial(1))
        assert db.pattern(one) is None  # one robot: the order is implied


def pick(session):
    """The pending trial told next: the second oldest (a fixed, not first-in-first-out, pattern)."""
    out = session.pending
    return out[min(1, len(out) - 1)]


def drive(session, task, *, stop_when_out=None):
    """Fill up to the learner's K, tell pick(); with ``stop_when_out``, return once that many are out."""
    while not session.done:
        while session.try_ask() is not None:
            pass
        if stop_when_out is not None and len(session.pending) >= stop_when_out:
            return True
        if session.done:
            break
        p = pick(session)
        session.tell(task.rollout(p.w), p.index)
    return False


def trials_of(path):
    with RunStore(path, readonly=True) as db:
        run = db.latest_run().id
        return [(r.index, r.proposal.w.tobytes(), r.outcome) for r in db.trials(run)], db.told_order(run), \
            db.pattern(run)


def test_a_crash_with_four_out_loses_none_and_ends_as_the_uninterrupted_run(task, tmp_path):
    with RunStore(tmp_path / "whole.corl") as db:
        whole = StoredRun.new(task, task_spec="synthetic", method="CORL", seed=0, robots=4, corl_overrides=FAST).attach(db)
        drive(whole, task)
        assert whole.done
    with RunStore(tmp_path / "cut.corl") as db:
        cut = StoredRun.new(task, task_spec="synthetic", method="CORL", seed=0, robots=4, corl_overrides=FAST).attach(db)
        assert drive(cut, task, stop_when_out=4), "the learner never had 4 trials out"
        out = [p.index for p in cut.pending]
    del cut  # the learner is gone; the robots' outcomes arrive after the restart
    with RunStore(tmp_path / "cut.corl") as db:
        again = StoredRun.open(db, task)
        assert [p.index for p in again.pending] == out and len(out) == 4
        with pytest.raises(StateError, match="name the one"):
            again.tell(Outcome(True, 0.0))
        drive(again, task)
        assert again.done and db.latest_run().status.value == "finished"
    assert trials_of(tmp_path / "cut.corl") == trials_of(tmp_path / "whole.corl")


SCRIPT = textwrap.dedent("""
    import os, signal, sys
    sys.path.insert(0, {tests!r})
    from test_session_parallel import FAST, drive
    from corl.session import StoredRun
    from corl.store import RunStore
    from corl.tasks.registry import load_task
    task = load_task("synthetic", seed=0)
    db = RunStore({path!r})
    run = StoredRun.new(task, task_spec="synthetic", method="CORL", seed=0, robots=4, corl_overrides=FAST).attach(db)
    if drive(run, task, stop_when_out=4):
        os.kill(os.getpid(), signal.SIGKILL)
""")


def test_sigkill_with_four_pending_then_the_late_tells(task, tmp_path):
    path = tmp_path / "killed.corl"
    script = SCRIPT.format(tests=os.path.dirname(__file__), path=str(path))
    done = subprocess.run([sys.executable, "-c", script], env={**os.environ, "OPENBLAS_NUM_THREADS": "1"},
                          capture_output=True, text=True, timeout=600)
    assert done.returncode == -signal.SIGKILL, done.stderr
    with RunStore(path) as db:
        run = StoredRun.open(db, task)
        out = run.pending
        assert len(out) == 4 and len(db.pending_trials(run.run_id)) == 4
        for p in reversed(out):  # the four robots report after the restart, newest first
            run.tell(task.rollout(p.w), p.index)
        assert not run.pending
        with pytest.raises(StateError, match="no pending trial"):  # each told once
            run.tell(task.rollout(out[0].w), out[0].index)
    with RunStore(path) as db:  # and the run goes on from there, replayed again
        run = StoredRun.open(db, task)
        drive(run, task)
        assert run.done and run.best is not None
        trials = db.trials(run.run_id)
        assert [r.index for r in trials] == list(range(len(trials))) and all(r.outcome for r in trials)
