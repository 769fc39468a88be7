"""Resume on another CPU (corl/store/resume.py): stored proposals that differ from the recomputed
ones in their last bits are what the robot executed, and the learner continues from them; a real
divergence stops with a message that names its likely cause."""

from __future__ import annotations

import contextlib
import json
import shutil
import sqlite3

import numpy as np
import pytest

from corl.session import StoredRun
from corl.store import RESUME_RTOL, RunStore, StoreError
from corl.store.machine import machine_info
from corl.tasks.registry import load_task

SEED = 1
KILLED_AT = 60  # trials stored before the "other CPU" run was killed


def ulps(x: np.ndarray, k: int = 3) -> np.ndarray:
    """``x`` moved ``k`` floating-point steps towards zero (as another BLAS kernel might round)."""
    for _ in range(k):
        x = np.nextafter(x, 0.0)
    return x


class OtherCPU:
    """A learner whose first ``n`` proposals come out a few ulps off, in place: it continues from them."""

    def __init__(self, learner, n: int) -> None:
        self.learner, self.n, self.moved = learner, n, set()

    def ask(self):
        p = self.learner.ask()
        if 0 < p.index < self.n and p.index not in self.moved:  # the demonstration is read, not computed
            p.w[...] = ulps(p.w)
            p.theta[...] = ulps(p.theta)
            self.moved.add(p.index)
        return p

    def tell(self, outcome):
        self.learner.tell(outcome)

    def __getattr__(self, name):
        return getattr(self.learner, name)


def backup(live, copy):
    """Copy a store that a writer has open (SQLite's online backup, as the README says)."""
    with contextlib.closing(sqlite3.connect(f"file:{live}?mode=ro", uri=True)) as src, \
            contextlib.closing(sqlite3.connect(copy)) as dst:
        src.backup(dst)


def trials(path):
    with RunStore(path, readonly=True) as db:
        return [(r.index, r.proposal.step, r.proposal.w.tobytes(), r.proposal.theta.tobytes(),
                 None if r.outcome is None else (r.outcome.success, r.outcome.return_))
                for r in db.trials(db.latest_run().id)]


@pytest.fixture(scope="module")
def other_cpu_run(tmp_path_factory):
    """A store killed after KILLED_AT trials computed "on another CPU", and that run finished there."""
    folder = tmp_path_factory.mktemp("cpu")
    task = load_task("synthetic", seed=SEED)
    with RunStore(folder / "run.corl") as db:
        session = StoredRun.start(db, task, task_spec="synthetic", method="CORL+PIBU", seed=SEED)
        session.learner = OtherCPU(session.learner, KILLED_AT)
        session.run(task, max_trials=KILLED_AT)
        backup(folder / "run.corl", folder / "killed.corl")  # the store as a kill at this moment leaves it
        session.run(task)
        assert session.done
        best = session.best
    return folder, best


def test_resume_continues_from_the_stored_proposals(other_cpu_run, tmp_path):
    folder, best = other_cpu_run
    store = tmp_path / "run.corl"
    shutil.copy(folder / "killed.corl", store)
    task = load_task("synthetic", seed=SEED)
    fresh = StoredRun  # this CPU recomputes every stored proposal: 59 of them differ by 3 ulps
    with RunStore(store) as db:
        session = fresh.open(db, task)
        assert len(session.history) == KILLED_AT
        session.run(task)
        assert session.done
        assert session.best.w.tobytes() == best.w.tobytes() and session.best.return_ == best.return_
    expected = trials(folder / "run.corl")
    assert len(expected) > KILLED_AT + 50
    assert trials(store) == expected  # the same trials, bit for bit, as the uninterrupted run


def test_recomputed_proposals_do_differ_in_their_last_bits(other_cpu_run):
    """The premise of the test above: the stored proposals are not what this CPU computes."""
    folder, _ = other_cpu_run
    task = load_task("synthetic", seed=SEED)
    from corl.experiments.methods import make_method

    learner = make_method("CORL+PIBU", task, seed=SEED)
    differ = 0
    for index, step, w, theta, outcome in trials(folder / "killed.corl")[:KILLED_AT]:
        p = learner.ask()
        stored_w = np.frombuffer(w)
        differ += p.w.tobytes() != w
        assert np.max(np.abs(p.w - stored_w)) <= RESUME_RTOL * max(1.0, np.max(np.abs(stored_w)))
        p.w[...] = stored_w
        p.theta[...] = np.frombuffer(theta)
        from corl.problem import Outcome

        learner.tell(Outcome(*outcome))
    assert differ == KILLED_AT - 1


def _damage(path, index: int, factor: float) -> None:
    with sqlite3.connect(path) as db:
        (blob,) = db.execute("SELECT w FROM trials WHERE trial_index = ?", (index,)).fetchone()
        w = np.frombuffer(blob, dtype="<f8") * factor
        db.execute("UPDATE trials SET w = ? WHERE trial_index = ?", (w.astype("<f8").tobytes(), index))


def test_a_real_divergence_stops_and_names_the_cause(other_cpu_run, tmp_path):
    folder, _ = other_cpu_run
    store = tmp_path / "run.corl"
    shutil.copy(folder / "killed.corl", store)
    _damage(store, 5, 1.0 + 1e-4)  # far beyond rounding: this is not the trial the learner computes
    task = load_task("synthetic", seed=SEED)
    with RunStore(store) as db:
        with pytest.raises(StoreError, match="stored trial 5: w differs by .*likely cause is the code or the "
                                             "configuration"):
            StoredRun.open(db, task)
    here = machine_info().get("blas_kernel", "unknown")
    other = "Haswell" if here == "Zen" else "Zen"  # a kernel this machine does not run
    with sqlite3.connect(store) as db:  # the run as recorded on a machine with another BLAS kernel
        (versions,) = db.execute("SELECT versions FROM runs").fetchone()
        db.execute("UPDATE runs SET versions = ?",
                   (json.dumps({**json.loads(versions), "blas_kernel": other, "cpu": "AMD EPYC 7B13"}),))
    with RunStore(store) as db:
        with pytest.raises(StoreError, match=f"Likely cause: this machine's software or processor differs .*"
                                             f"blas_kernel {other} -> {here}.*cpu AMD EPYC 7B13"):
            StoredRun.open(db, task)
    assert len(trials(store)) == KILLED_AT  # nothing was added or replaced
