"""A real-robot loop never proposes a w that already failed (issue 12, item 4).

The task's success depends on the path, not only on theta (against Sec. IV's assumption): the
optimization step drives ``w[1]`` towards 2 with theta fixed, and every trajectory with
``w[1] > 1.1`` fails. Before the fix, round 1's optimization step started from the same ``w*`` as
round 0's and proposed the identical failing w again.
"""

import numpy as np
import pytest

from corl.errors import InputError
from corl.experiments.methods import make_method
from corl.learner import CORL, CORLConfig
from corl.optimizers.base import BlackBoxOptimizer
from corl.problem import Bounds, Demonstration, Outcome
from corl.settings import MethodSettings

LIMIT = 1.1  # w[1] beyond this fails, whatever theta


class PathTask:
    """w = (contact, reach, spare) (3,); theta = w[0]; J = (w[1] - 2)^2; S needs w[1] < LIMIT, |theta| < 0.4."""

    name = "path"
    theta_bounds = Bounds(np.array([-1.0]), np.array([1.0]))
    w_bounds = None

    def __init__(self, w0=(0.0, 0.0, 0.3)):
        self.w0 = np.asarray(w0, dtype=float)
        self.rollouts = []

    def demonstration(self):
        return Demonstration(self.w0.copy(), np.array([self.w0[0]]))

    def cost_residuals(self, w):
        return np.array([w[1] - 2.0]), np.array([[0.0, 1.0, 0.0]])

    def constraint(self, w, theta):
        return np.array([w[0] - theta[0]]), np.array([[1.0, 0.0, 0.0]])

    def theta_of(self, w):
        return np.array([w[0]])

    def rollout(self, w):
        self.rollouts.append(np.array(w, dtype=float))
        theta = float(w[0])
        if w[1] > LIMIT or abs(theta) >= 0.4:
            return Outcome(False)
        return Outcome(True, 1.0 - (theta - 0.1) ** 2)


class Scripted(BlackBoxOptimizer):
    """Proposes a fixed list of thetas, then stops."""

    def __init__(self, bounds, thetas):
        super().__init__(bounds, max_evals=len(thetas) + 10, name="scripted")
        self._queue = [np.array([t]) for t in thetas]

    def _propose(self):
        return self._queue.pop(0) if self._queue else None

    def _observe(self, x, outcome):
        pass


def assert_no_failed_w_repeated(learner, eps):
    failed = []
    for p, o in learner.history:
        assert all(np.linalg.norm(p.w - f) >= eps for f in failed), f"trial {p.index} repeats a failed w"
        if not o.success:
            failed.append(p.w)
    return failed


def test_the_issue_scenario_never_repeats_the_failed_step():
    task = PathTask()
    cfg = CORLConfig(eps_max=0.25, eps_w=1e-6, max_rounds=10)
    # step 2 finds nothing better than theta0 = 0: theta* stays, but w* moved, so a second round runs
    learner = CORL(task, lambda b, x0, rng: Scripted(b, [0.35]), cfg)
    learner.run(task)
    failed = assert_no_failed_w_repeated(learner, cfg.eps_w)
    steps = [(p.round, p.step, o.success) for p, o in learner.history]
    # the situation of the issue: round 0's optimization step failed, and round 1 started from the same w*
    assert (0, "optimization", False) in steps
    assert any(r == 1 and s == "optimization" for r, s, _ in steps)
    opt = [(p, o) for p, o in learner.history if p.step == "optimization"]
    reach = [float(p.w[1]) for p, _ in opt]
    assert reach == pytest.approx([0.25, 0.5, 0.75, 1.0, 1.25, 1.125])  # the trust region halves at each failure
    assert len(failed) == 2 and learner.eps_max == pytest.approx(0.0625)
    assert learner.best.w[1] == pytest.approx(1.0)
    assert len(task.rollouts) == len(learner.history)


def test_a_failure_after_a_success_at_half_radius_is_refused_without_a_rollout():
    # round 2 from w* = 1.0 with radius 1/16 reaches 1.0625 (success); its next step, 1.125 (theta* the
    # same), failed in round 1: it is not proposed again
    task = PathTask()
    cfg = CORLConfig(eps_max=0.25, eps_w=1e-6, max_rounds=10)
    rounds = iter([[0.35], [0.12], [], [], []])  # round 1 moves theta* to 0.12, so round 2 runs too
    learner = CORL(task, lambda b, x0, rng: Scripted(b, next(rounds)), cfg)
    learner.run(task)
    assert_no_failed_w_repeated(learner, cfg.eps_w)
    assert learner.best.theta[0] == pytest.approx(0.12)


@pytest.mark.parametrize("rollout_every_step", [True, False])
def test_pibu_on_a_path_dependent_task_never_repeats_a_failure(rollout_every_step):
    task = PathTask()
    corl = CORLConfig(eps_max=0.3, eps_w=1e-6, max_rounds=10, rollout_every_step=rollout_every_step, max_rl_trials=15)
    settings = MethodSettings(corl=corl)
    learner = make_method("CORL+PIBU", task, seed=3, settings=settings)
    learner.run(task)
    failed = assert_no_failed_w_repeated(learner, corl.eps_w)
    assert failed  # the task does fail: the test would see a repetition
    if rollout_every_step:  # stepwise, J falls until the reach limit; at once, the one step fails
        assert learner.best.J < (LIMIT - 2.0) ** 2 + 0.1


def test_a_theta_whose_trajectory_failed_is_told_its_failure_without_a_rollout():
    task = PathTask(w0=(0.0, 0.0, 0.0))
    cfg = CORLConfig(eps_max=0.25, eps_w=1e-6, max_rounds=1, max_optimization_steps=1)
    learner = CORL(task, lambda b, x0, rng: Scripted(b, [0.5, 0.5, 0.2]), cfg)
    learner.run(task)
    assert_no_failed_w_repeated(learner, cfg.eps_w)
    thetas = [float(p.theta[0]) for p, _ in learner.history if p.step == "reinforcement"]
    assert thetas == pytest.approx([0.5, 0.2])  # the second 0.5 realises the same w: known, not rolled out
    assert learner.known_failures == 1
    data = learner.optimizers[0]
    assert list(data.success_[-3:]) == [False, False, True]


def test_a_demonstration_off_h_is_refused_before_any_rollout():
    class Off(PathTask):
        def demonstration(self):
            return Demonstration(self.w0.copy(), np.array([0.02]))  # w0 realises theta = 0, not 0.02

    task = Off()
    with pytest.raises(InputError, match=r"max\|h\(w0, theta0\)\| = 0.02 .*corl.realise.project_demonstration"):
        CORL(task, lambda b, x0, rng: Scripted(b, []))
    assert task.rollouts == []
    loose = CORL(task, lambda b, x0, rng: Scripted(b, []), CORLConfig(demo_tolerance=0.05))  # a task may state its own
    assert loose.ask().step == "demonstration"


def test_project_demonstration_moves_w0_onto_h():
    from corl.realise import check_demonstration, constraint_violation, project_demonstration

    task = PathTask()
    demo, before, moved = project_demonstration(task, Demonstration(task.w0, np.array([0.02])))
    assert before == pytest.approx(0.02)
    assert moved == pytest.approx(0.02)  # the closest point moves w[0] alone
    assert constraint_violation(task, demo.w, demo.theta) < 1e-9
    check_demonstration(task, demo)
