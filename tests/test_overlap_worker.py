"""Rollouts in a forked worker process (corl.tasks.worker): outcomes, the child's errors, its death,
its shutdown, and StoredRun.run with a task that opts in (same trials as in one process)."""

import multiprocessing
import os
import time

import numpy as np
import pytest

from corl.errors import RolloutError
from corl.problem import Outcome
from corl.session import StoredRun
from corl.store import RunStore
from corl.tasks.worker import RolloutWorker, WorkerError, wants_worker
from test_learner_phase import WaypointTask


class Picky(Exception):
    def __init__(self, a, b):  # cannot be rebuilt from its args: goes back as text
        super().__init__(f"{a} and {b}")


class Fake:
    rollout_in_worker = True

    def __init__(self, mode="ok"):
        self.mode = mode
        self.calls = 0

    def rollout(self, w):
        self.calls += 1  # the fork's copy counts, not the parent's
        w = np.asarray(w)
        if self.mode == "raise":
            raise ValueError(f"bad w of size {w.size}")
        if self.mode == "picky":
            raise Picky("x", "y")
        if self.mode == "die":
            os._exit(7)
        if self.mode == "hang":
            time.sleep(30)
        return Outcome(True, float(w.sum()), {"pid": os.getpid()})


def children():
    return [p for p in multiprocessing.active_children() if p.name == "corl-rollout"]


def test_outcomes_come_from_the_child_and_close_ends_it():
    task = Fake()
    with RolloutWorker(task) as worker:
        out = worker.rollout(np.array([1.0, 2.0]))
        assert out == Outcome(True, 3.0, {"pid": worker.pid}) and worker.pid != os.getpid()
        assert worker.rollout([0.5]).return_ == 0.5
    assert task.calls == 0 and children() == []


def test_a_child_error_is_raised_here_with_its_type_and_message():
    with RolloutWorker(Fake("raise")) as worker:
        with pytest.raises(ValueError, match="bad w of size 2"):
            worker.rollout(np.zeros(2))
        with pytest.raises(ValueError):  # the child lives on
            worker.rollout(np.zeros(1))
    with RolloutWorker(Fake("picky")) as worker:
        with pytest.raises(Exception, match="x and y") as info:
            worker.rollout(np.zeros(2))
        assert type(info.value).__name__ == "Picky"


def test_a_dead_child_is_a_clear_error_not_a_hang():
    worker = RolloutWorker(Fake("die"))
    t0 = time.perf_counter()
    with pytest.raises(WorkerError, match=r"died \(exit code 7\)"):
        worker.rollout(np.zeros(2))
    with pytest.raises(WorkerError, match="died"):  # and stays an error
        worker.rollout(np.zeros(2))
    assert time.perf_counter() - t0 < 5.0
    worker.close()
    assert children() == []


def test_a_child_that_does_not_answer_times_out_and_is_ended():
    worker = RolloutWorker(Fake("hang"), timeout=0.5)
    with pytest.raises(WorkerError, match="did not answer within 0.5 s"):
        worker.rollout(np.zeros(2))
    assert children() == []


def test_only_tasks_that_opt_in_get_a_worker():
    assert wants_worker(Fake()) and not wants_worker(WaypointTask())
    other = Fake()
    other.rollout_in_worker = "yes"
    assert not wants_worker(other)


class ForkedWaypoints(WaypointTask):
    rollout_in_worker = True
    fail_at = ()

    def rollout(self, w):
        if self.fail_at == "raise":
            raise RuntimeError("the simulator broke")
        if self.fail_at == "die":
            os._exit(3)
        return Outcome(True, float(np.round(np.sum(w), 6)))


def stored(tmp_path, name, task, **kwargs):
    from corl.methods import make_method

    db = RunStore(tmp_path / f"{name}.corl")
    run = StoredRun(make_method("CORL", task, seed=0), None, None)
    run._record = {"task": task.name, "method": "CORL", "seed": 0, "config": {}}
    run.attach(db)
    return run, db


def trials(run):
    return [(p.index, p.step, p.w.tobytes(), p.theta.tobytes(), o.success, o.return_) for p, o in run.history]


def test_stored_run_in_a_worker_gives_the_trials_of_one_process(tmp_path):
    one, _ = stored(tmp_path, "one", ForkedWaypoints())
    one.run(one.learner.task, worker=False, max_trials=25)
    two, _ = stored(tmp_path, "two", ForkedWaypoints())
    two.run(two.learner.task, max_trials=25)
    assert trials(one) == trials(two) and len(trials(one)) == 25
    assert two.learner.speculative is False and children() == []


@pytest.mark.parametrize("mode, message", [("raise", "raised RuntimeError: the simulator broke"),
                                           ("die", "raised WorkerError: the rollout worker process .* died")])
def test_stored_run_errors_keep_the_trial_pending_and_end_the_worker(tmp_path, mode, message):
    task = ForkedWaypoints()
    run, db = stored(tmp_path, mode, task)
    run.run(task, max_trials=3)
    task.fail_at = mode
    with pytest.raises(RolloutError, match=message):
        run.run(task)
    assert children() == [] and db.pending(run.run_id) is not None


def test_keyboard_interrupt_ends_the_worker(tmp_path):
    task = ForkedWaypoints()
    run, _ = stored(tmp_path, "kb", task)

    def interrupt(p, o):
        if p.index == 4:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        run.run(task, callback=interrupt)
    assert children() == [] and run.learner.speculative is False
    assert run.learner._speculation is None or not run.learner._speculation._thread.is_alive()


def test_the_child_dies_with_its_parent(tmp_path):
    """A parent killed outright (kill -9) leaves no child behind holding its files (the store's lock)."""
    import signal
    import subprocess
    import sys

    script = (
        "import os, signal, sys, numpy as np\n"
        "from corl.tasks.worker import RolloutWorker\n"
        "from corl.problem import Outcome\n"
        "class T:\n"
        "    def rollout(self, w): return Outcome(True, 1.0)\n"
        "w = RolloutWorker(T()); w.rollout(np.zeros(1))\n"
        "print(w.pid, flush=True)\n"
        "os.kill(os.getpid(), signal.SIGKILL)\n"
    )
    out = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=60)
    assert out.returncode == -signal.SIGKILL, out.stderr
    child = int(out.stdout.split()[0])
    deadline = time.time() + 5.0
    while time.time() < deadline:
        try:
            os.kill(child, 0)
        except ProcessLookupError:
            return
        time.sleep(0.05)
    pytest.fail(f"the worker {child} outlived its parent")


def test_check_task_refuses_a_rollout_in_worker_that_is_not_a_bool():
    from corl.errors import InputError
    from corl.problem import check_task
    from corl.tasks.synthetic import SyntheticTask

    class Odd(SyntheticTask):
        rollout_in_worker = "yes"

    with pytest.raises(InputError, match="'rollout_in_worker' must be True or False"):
        check_task(Odd())

    class Fine(SyntheticTask):
        rollout_in_worker = False

    check_task(Fine())


class Formatted(Exception):
    def __init__(self, step):  # pickles and unpickles, but with another message: goes back as text
        super().__init__(f"the simulation diverged at step {step}")


class Formats(Fake):
    def rollout(self, w):
        raise Formatted(17)


def test_an_error_that_would_come_back_changed_keeps_its_message():
    with RolloutWorker(Formats()) as worker:
        with pytest.raises(Exception, match=r"^the simulation diverged at step 17$") as err:
            worker.rollout([1.0])
    assert type(err.value).__name__ == "Formatted"


def test_an_interrupted_wait_breaks_the_worker_instead_of_answering_the_next_w(monkeypatch):
    import corl.tasks.worker as worker_module

    worker = RolloutWorker(Fake())
    try:
        def interrupted(*args, **kwargs):
            raise KeyboardInterrupt

        monkeypatch.setattr(worker_module, "wait", interrupted)
        with pytest.raises(KeyboardInterrupt):
            worker.rollout([5.0])
        monkeypatch.undo()
        with pytest.raises(WorkerError, match="interrupted"):  # never the answer meant for [5.0]
            worker.rollout([1.0])
    finally:
        worker.close()
    assert children() == []


def test_a_learner_that_only_passes_attributes_on_gets_no_worker(tmp_path, monkeypatch):
    # ContextualCORL hands attribute lookups to its inner CORL: it must not look like a learner that
    # speculates (the worker would be forked for nothing, and settle() fails once no start is left)
    import corl.tasks.worker as worker_module

    class Passes:
        def __init__(self, inner):
            self._inner = inner

        def __getattr__(self, name):
            return getattr(self._inner, name)

    task = WaypointTask()
    task.rollout_in_worker = True
    run = StoredRun.new(task, task_spec="x", method="CORL", seed=0)
    run.learner = Passes(run.learner)
    monkeypatch.setattr(worker_module, "RolloutWorker", lambda *a, **k: pytest.fail("a worker was started"))
    with RunStore(tmp_path / "s.corl") as db:
        run.attach(db)
        run.run(task, max_trials=3)
    assert len(run.history) == 3


def test_a_fork_that_fails_runs_the_same_trials_in_this_process(tmp_path, monkeypatch):
    import corl.tasks.worker as worker_module

    def no_fork(*args, **kwargs):
        raise OSError(11, "Resource temporarily unavailable")

    monkeypatch.setattr(worker_module, "RolloutWorker", no_fork)
    runs = []
    for name, worker in (("a", True), ("b", False)):
        task = WaypointTask()
        task.rollout_in_worker = True
        with RunStore(tmp_path / f"{name}.corl") as db:
            run = StoredRun.new(task, task_spec="x", method="CORL", seed=0).attach(db)
            run.run(task, max_trials=6, worker=worker)
            runs.append(run.history)
    assert len(runs[0]) == len(runs[1]) == 6
    assert all(np.array_equal(p.w, q.w) and o == r for (p, o), (q, r) in zip(*runs))
