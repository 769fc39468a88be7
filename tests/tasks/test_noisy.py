"""NoisyTask (corl/tasks/noisy.py) and `corl run --return-noise --flip`: the noise has the requested
std, labels flip at the requested rate, the truth is in info, readings are reproducible (in a forked
worker and across a resume too), the wrapped task's members pass through, bad settings are refused."""

from __future__ import annotations

import copy
import json
import math
import pickle

import numpy as np
import pytest
from typer.testing import CliRunner

from corl.cli import app
from corl.errors import InputError
from corl.problem import Outcome, Proposal, check_task
from corl.session import StoredRun
from corl.store import RunStore
from corl.tasks import NoisyTask
from corl.tasks.registry import load_task
from corl.tasks.synthetic import ContextualSyntheticTask, SyntheticTask, return_of
from corl.tasks.worker import RolloutWorker

runner = CliRunner()
N = 4000  # rollouts per statistic: the std of a rate q is sqrt(q (1 - q) / N) < 0.008


def safe_ws(n: int, seed: int = 0) -> np.ndarray:
    """(n, 2) synthetic w's inside the success interval theta in (-1.5, 2.5), all different."""
    theta = np.random.default_rng(seed).uniform(-1.4, 2.4, n)
    return np.column_stack([np.cos(theta), np.sin(theta)])


class Measured(SyntheticTask):
    """The synthetic task, but a failure also reports the return it computed (as a robot task may)."""

    def rollout(self, w):
        theta = math.atan2(w[1], w[0])
        return Outcome(-1.5 < theta < 2.5, return_of(theta), {"theta": theta})


def test_the_return_noise_has_the_requested_std_and_no_bias():
    task = NoisyTask(SyntheticTask(), return_noise=0.3, seed=1)
    errors = []
    for w in safe_ws(N):
        o = task.rollout(w)
        assert o.success and o.info["true_success"] and not o.info["flipped"]
        assert o.info["true_return"] == SyntheticTask().rollout(w).return_
        errors.append(o.return_ - o.info["true_return"])
    assert np.std(errors) == pytest.approx(0.3, rel=0.05)
    assert abs(np.mean(errors)) < 4 * 0.3 / math.sqrt(N)


def test_labels_flip_at_the_requested_rate_both_ways():
    task = NoisyTask(Measured(), return_noise=0.1, flip=0.2, seed=2)
    theta = np.random.default_rng(3).uniform(-3.1, 3.1, N)  # about 64 % inside the success interval
    outcomes = [task.rollout(np.array([math.cos(t), math.sin(t)])) for t in theta]
    truth = np.array([o.info["true_success"] for o in outcomes])
    flipped = np.array([o.info["flipped"] for o in outcomes])
    assert np.array_equal(flipped, np.array([o.success for o in outcomes]) != truth)
    for was in (True, False):
        assert flipped[truth == was].mean() == pytest.approx(0.2, abs=0.03)
    for o in outcomes:
        if o.info["true_success"] and not o.success:
            assert o.return_ is None  # a failure observes no return
        else:  # reported with the sensor's error, also a failure the task measured a return for
            assert o.return_ != o.info["true_return"] and abs(o.return_ - o.info["true_return"]) < 1.0


def test_a_failure_without_a_return_and_the_demonstration_never_flip():
    task = NoisyTask(SyntheticTask(), flip=0.45, seed=0)
    unsafe = [task.rollout(np.array([math.cos(t), math.sin(t)])) for t in np.linspace(2.6, 3.1, 200)]
    assert all(not o.success and o.return_ is None and not o.info["flipped"] for o in unsafe)
    w0 = SyntheticTask().demonstration().w
    for seed in range(100):  # P(no flip of an ordinary w in 100 seeds) = 0.55^100
        assert NoisyTask(SyntheticTask(), flip=0.45, seed=seed).rollout(w0).success
    assert any(not NoisyTask(SyntheticTask(), flip=0.45, seed=s).rollout(np.array([1.0, 0.2])).success
               for s in range(100))


def test_readings_are_a_function_of_seed_w_and_its_repeats_alone():
    ws = safe_ws(50)
    task = NoisyTask(Measured(), return_noise=0.2, flip=0.3, seed=7)
    first = [task.rollout(w) for w in ws]
    fresh = NoisyTask(Measured(), return_noise=0.2, flip=0.3, seed=7)
    assert [fresh.rollout(w) for w in ws[::-1]] == first[::-1]  # the order of the w's does not matter
    for other in (pickle.loads(pickle.dumps(fresh)), copy.copy(fresh)):  # the counts travel with a copy
        assert [other.rollout(w) for w in ws] != first
        other.recount([])
        assert [other.rollout(w) for w in ws] == first
    reseeded = [NoisyTask(Measured(), return_noise=0.2, flip=0.3, seed=8).rollout(w) for w in ws]
    assert sum(a.return_ == b.return_ for a, b in zip(first, reseeded)) < 5
    exact = NoisyTask(Measured(), seed=7)  # the same draws: only their scale differs
    assert all(o.success == e.success == e.info["true_success"] and e.return_ == e.info["true_return"]
               for o, e in zip(first, (exact.rollout(w) for w in ws)) if not o.info["flipped"])


def test_a_repeated_trial_reads_afresh_and_a_recount_goes_on_where_a_run_stopped():
    w, other = safe_ws(2)
    task = NoisyTask(SyntheticTask(), return_noise=0.3, seed=1)
    readings = [task.rollout(w).return_ for _ in range(N // 4)]
    assert len(set(readings)) == len(readings) and np.std(readings) == pytest.approx(0.3, rel=0.1)
    order = [w, other, w, w, other, w]
    whole = [o.return_ for o in map(NoisyTask(SyntheticTask(), return_noise=0.3, seed=1).rollout, order)]
    resumed = NoisyTask(SyntheticTask(), return_noise=0.3, seed=1)  # a new process: the first three were told
    resumed.recount(order[:3])
    assert [resumed.rollout(v).return_ for v in order[3:]] == whole[3:]
    resumed.recount(order[:3])
    with RolloutWorker(resumed) as worker:  # forked with its counts
        assert [worker.rollout(v).return_ for v in order[3:]] == whole[3:]


class Repeater:
    """A learner that asks the w's it is given, in order (some more than once), then is done."""

    def __init__(self, ws):
        self.ws, self.history, self.best, self._asked = ws, [], None, None

    @property
    def done(self):
        return len(self.history) == len(self.ws)

    def ask(self):
        self._asked = Proposal(len(self.history), self.ws[len(self.history)], np.zeros(1), "search")
        return self._asked

    def tell(self, outcome):
        self.history.append((self._asked, outcome))


def test_stored_run_counts_the_told_trials_of_a_run_before_it_rolls_out(tmp_path):
    """What `corl run --resume` does: a new process (a new NoisyTask) goes on from the stored trials."""
    ws = [w for w in safe_ws(4) for _ in range(3)]  # each w three times

    def stored(name):
        run = StoredRun(Repeater(ws), None, None)
        run._record = {"task": "synthetic", "method": "repeat", "seed": 0, "config": {}}
        return run.attach(RunStore(tmp_path / f"{name}.corl"))

    def sensors():
        return NoisyTask(Forked(), return_noise=0.1, flip=0.2, seed=9)

    whole = stored("whole")
    whole.run(sensors(), worker=False)
    killed = stored("killed")
    killed.run(sensors(), max_trials=5)
    killed.run(sensors())  # a new task, as after a resume: counted from the 5 told trials
    assert [o for _, o in killed.history] == [o for _, o in whole.history]
    returns = [o.return_ for _, o in whole.history if o.return_ is not None]
    assert len(set(returns)) == len(returns) >= 6  # the repeats read afresh


@pytest.mark.parametrize("kwargs, message", [
    (dict(return_noise=-0.1), "return_noise must be a finite standard deviation >= 0"),
    (dict(return_noise=math.nan), "return_noise must be a finite"),
    (dict(return_noise=math.inf), "return_noise must be a finite"),
    (dict(return_noise="0.1"), "return_noise must be"),
    (dict(flip=0.5), r"flip must be a probability in \[0, 0.5\)"),
    (dict(flip=-0.01), "flip must be a probability"),
    (dict(flip=math.nan), "flip must be a probability"),
    (dict(flip=True), "flip must be a probability"),
    (dict(seed=-1), "seed must be an integer >= 0"),
    (dict(seed=0.5), "seed must be an integer >= 0"),
])
def test_bad_settings_are_refused_in_one_line(kwargs, message):
    with pytest.raises(InputError, match=message) as info:
        NoisyTask(SyntheticTask(), **kwargs)
    assert "\n" not in str(info.value)


def test_a_non_task_is_refused():
    with pytest.raises(InputError, match="the task NoisyTask wraps .* is not a task"):
        NoisyTask(object(), return_noise=0.1)


def test_every_member_passes_through_and_new_tasks_keep_the_sensors():
    inner = ContextualSyntheticTask(SyntheticTask().w0)
    task = check_task(NoisyTask(inner, return_noise=0.1, flip=0.1, seed=4))
    assert task.name == inner.name and task.theta_bounds is inner.theta_bounds
    assert task.method_settings() == inner.method_settings() and task.context_bounds is inner.context_bounds
    assert getattr(task, "spline", None) is None and getattr(task, "rollout_in_worker", None) is None
    scene = task.with_context([0.5])
    assert isinstance(scene, NoisyTask) and scene.noise == task.noise
    assert scene.wrapped.context == pytest.approx([0.5])
    w = safe_ws(1)[0]
    assert scene.rollout(w).info["true_return"] == inner.with_context([0.5]).rollout(w).return_

    class Retimable(SyntheticTask):
        rollout_in_worker = True
        spline = "a spline"

        def retimed(self, time_map):
            return Retimable(self.w0 * time_map(1.0))

    task = NoisyTask(Retimable(), flip=0.2)
    assert task.rollout_in_worker is True and task.spline == "a spline"
    again = task.retimed(lambda t: 2 * t)
    assert isinstance(again, NoisyTask) and again.noise == task.noise and np.allclose(again.wrapped.w0, 2 * task.w0)


class Forked(SyntheticTask):
    """The synthetic task as a simulator that opts in to rollouts in a worker (corl.tasks.worker)."""

    rollout_in_worker = True


def test_a_run_in_a_worker_reads_the_sensors_of_a_run_in_one_process(tmp_path):
    def history(worker: bool):
        task = NoisyTask(Forked(SyntheticTask.random_start(np.random.default_rng(5))), return_noise=0.05,
                         flip=0.1, seed=3)
        with RunStore(tmp_path / f"{worker}.corl") as db:
            run = StoredRun.start(db, task, task_spec="synthetic", method="CORL", seed=3)
            assert db.run(run.run_id).config["noise"] == {"return_noise": 0.05, "flip": 0.1, "seed": 3}
            run.run(task, worker=worker)
            return [(p.w.tobytes(), o.success, o.return_, o.info["flipped"]) for p, o in run.history]

    one, two = history(False), history(True)
    assert one == two and any(flipped for *_, flipped in one) and len(one) > 10


# -- corl run --return-noise --flip ------------------------------------------------------------------
def test_corl_run_reads_the_task_through_the_sensors_and_records_them(tmp_path):
    res = runner.invoke(app, ["run", "synthetic", "--return-noise", "0.01", "--flip", "0.0", "--out",
                              str(tmp_path / "a"), "--quiet", "--json"])
    assert res.exit_code == 0, res.output
    summary = json.loads((tmp_path / "a" / "summary.json").read_text())
    assert summary["noise"] == {"return_noise": 0.01, "flip": 0.0, "seed": 0}
    true = summary["final_info"]["true_return"]
    assert true != summary["best_return"] and abs(true - summary["best_return"]) < 0.05
    with RunStore(tmp_path / "a" / "run.corl", readonly=True) as db:
        outcomes = [t.outcome for t in db.trials(db.latest_run().id)]
    assert all("true_return" in o.info for o in outcomes)
    clean = runner.invoke(app, ["run", "synthetic", "--out", str(tmp_path / "b"), "--quiet"])
    assert clean.exit_code == 0 and "noise" not in json.loads((tmp_path / "b" / "summary.json").read_text())


def test_corl_run_resume_continues_with_the_recorded_sensors(tmp_path):
    args = ["--return-noise", "0.05", "--flip", "0.2", "--seed", "2", "--quiet"]
    whole = runner.invoke(app, ["run", "synthetic", *args, "--out", str(tmp_path / "whole")])
    assert whole.exit_code == 0, whole.output
    task = NoisyTask(load_task("synthetic", seed=2), return_noise=0.05, flip=0.2, seed=2)
    with RunStore(tmp_path / "killed.corl") as db:  # a run killed after 12 trials
        StoredRun.start(db, task, task_spec="synthetic", method="CORL+PIBU", seed=2).run(task, max_trials=12)
    for refused, flag in ((["--flip", "0.1"], "--flip 0.1 differs"), (["--return-noise", "0"], "--return-noise 0.0")):
        res = runner.invoke(app, ["run", "synthetic", "--store", str(tmp_path / "killed.corl"), "--resume",
                                  "--out", str(tmp_path / "r"), *refused])
        assert res.exit_code == 2 and flag in res.stderr and "run 1 has" in res.stderr, res.output
    res = runner.invoke(app, ["run", "synthetic", "--store", str(tmp_path / "killed.corl"), "--resume",
                              "--flip", "0.2", "--out", str(tmp_path / "resumed"), "--quiet"])
    assert res.exit_code == 0, res.output

    def trials(path):
        with RunStore(path, readonly=True) as db:
            return [(t.proposal.w.tobytes(), t.outcome.success, t.outcome.return_) for t in db.trials(1)]

    assert trials(tmp_path / "killed.corl") == trials(tmp_path / "whole" / "run.corl")
    assert json.loads((tmp_path / "resumed" / "summary.json").read_text())["noise"]["flip"] == 0.2


@pytest.mark.parametrize("args, message", [
    (["--return-noise", "-1"], "--return-noise must be a finite standard deviation >= 0"),
    (["--return-noise", "nan"], "--return-noise must be a plain finite number"),
    (["--return-noise", "1_0"], "--return-noise must be a plain finite number"),
    (["--flip", "0.5"], r"--flip must be a probability in [0, 0.5)"),
    (["--flip", "abc"], "--flip must be a plain finite number"),
])
def test_corl_run_refuses_bad_sensor_values_with_exit_2(tmp_path, args, message):
    res = runner.invoke(app, ["run", "synthetic", *args, "--out", str(tmp_path / "o")])
    assert res.exit_code == 2, res.output
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: ") and message in lines[0], res.stderr
    assert not (tmp_path / "o").exists()


@pytest.mark.slow
def test_the_door_in_a_worker_reads_its_sensors_in_the_child():
    pytest.importorskip("mujoco")
    from corl.tasks.door.task import DoorTask

    task = NoisyTask(DoorTask(), return_noise=0.05, flip=0.3, seed=1)
    assert check_task(task).rollout_in_worker is True and task.theta_labels == DoorTask.theta_labels
    w0 = task.demonstration().w
    here = task.rollout(w0)
    task.recount([])  # as before that rollout: the child reads w0's first values too
    with RolloutWorker(task) as worker:
        there = worker.rollout(w0)
    assert here == there and here.success and here.return_ != here.info["true_return"]
    assert isinstance(task.retimed(lambda t: t), NoisyTask)

