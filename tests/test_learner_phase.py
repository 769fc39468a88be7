"""Phase steps inside Algorithm 1 (Sec. VI-B): accepted, and moving the contact instants with them."""

import copy

import numpy as np
import pytest

from corl.learner import CORL, CORLConfig, cost_of
from corl.optimizers.base import BlackBoxOptimizer
from corl.problem import Bounds, Demonstration, Outcome
from corl.realise import project_demonstration
from corl.trajectory.bspline import BSpline
from corl.trajectory.features import TrajectoryProblem, acceleration_feature, configuration_feature


class Nothing(BlackBoxOptimizer):
    """A black-box step that proposes nothing: these tests are about the optimization step."""

    def __init__(self, bounds):
        super().__init__(bounds, max_evals=1, name="nothing")

    def _propose(self):
        return None


class WaypointTask:
    """A 2-DoF path through fixed points at badly spread instants (the demonstration rushes the
    first legs): ``h`` pins the path's position at each instant; theta shifts the last point."""

    name = "waypoints"
    theta_bounds = Bounds(np.array([-0.5]), np.array([0.5]))
    w_bounds = None

    def __init__(self, retimable: bool = True):
        self.spline = BSpline(30, 2, duration=1.0)
        self.contact_times = np.array([0.15, 0.3, 0.85])
        self.points = np.array([[1.0, 0.0], [1.0, 1.0], [2.0, 1.5]])
        self._cost = TrajectoryProblem(self.spline.n, costs=[acceleration_feature(self.spline, 60)])
        if not retimable:
            self.pinned_times = tuple(self.contact_times)
        self.rollouts = 0

    def retimed(self, time_map):
        task = copy.copy(self)
        task.contact_times = np.asarray(time_map(self.contact_times), dtype=float)
        return task

    def demonstration(self):
        t = np.linspace(0.0, 1.0, 201)
        knots_t = np.concatenate([[0.0], self.contact_times, [1.0]])
        knots_q = np.vstack([[0.0, 0.0], self.points, self.points[-1]])
        q = np.stack([np.interp(t, knots_t, knots_q[:, j]) for j in range(2)], axis=1)
        fitted = Demonstration(self.spline.fit(t, q), np.array([0.0]))  # misses its points by ~0.02
        return project_demonstration(self, fitted)[0]  # onto h = 0: CORL checks h(w0, theta0) ~ 0

    def cost_residuals(self, w):
        return self._cost.residuals(w)

    def constraint(self, w, theta):
        points = self.points.copy()
        points[-1, 0] += float(np.asarray(theta)[0])
        eqs = [configuration_feature(self.spline, 0.0, np.zeros(2))]
        eqs += [configuration_feature(self.spline, float(t), p) for t, p in zip(self.contact_times, points)]
        return TrajectoryProblem(self.spline.n, costs=[acceleration_feature(self.spline, 4)], equalities=eqs).equalities(w)

    def theta_of(self, w):
        return np.array([self.spline.positions(w, [self.contact_times[-1]])[0, 0] - self.points[-1, 0]])

    def rollout(self, w):
        self.rollouts += 1
        return Outcome(True, 0.0)


def run(task, **config):
    cfg = CORLConfig(eps_max=0.5, eps_w=1e-6, max_rounds=1, max_optimization_steps=30, **config)
    learner = CORL(task, lambda b, x0, rng: Nothing(b), cfg)
    learner.run(task)
    return learner


def test_phase_steps_are_accepted_and_move_the_contact_instants():
    task = WaypointTask()
    learner = run(task, max_phase_steps=10)
    steps = [p.step for p, _ in learner.history]
    assert "phase" in steps, steps
    last_opt = max(i for i, s in enumerate(steps) if s == "optimization")
    J_traj = cost_of(task, learner.history[last_opt][0].w)
    assert learner.best.J < 0.9 * J_traj  # re-timing lowers J beyond the trajectory steps' optimum
    moved = learner.task.contact_times
    assert moved is not task.contact_times and not np.allclose(moved, task.contact_times)
    assert np.all(np.diff(moved) > 0)
    # the first two legs were rushed (1 m in 0.15 s each, then 1.1 m in 0.55 s): they get more time
    assert moved[0] > task.contact_times[0] and moved[1] > task.contact_times[1]
    # w* still meets Eq. 6 at the re-timed instants, and theta is unchanged
    h, _ = learner.task.constraint(learner.best.w, learner.best.theta)
    assert np.max(np.abs(h)) < 1e-4
    assert learner.best.theta == pytest.approx([0.0])
    # the task the user passed in is not modified
    assert task.contact_times.tolist() == [0.15, 0.3, 0.85]


def test_without_retimed_the_contact_instants_keep_their_phase():
    task = WaypointTask(retimable=False)
    task.retimed = None  # the protocol hook is optional
    learner = run(task, max_phase_steps=10)
    assert learner.task is task
    for p, _ in learner.history[1:]:  # trial 0 is the demonstration, a B-spline fit
        h, _ = task.constraint(p.w, p.theta)
        assert np.max(np.abs(h)) < 1e-4


@pytest.mark.parametrize("fraction", [0.05, 0.2])
def test_min_J_decrease_ends_a_chain_whose_step_buys_too_little(fraction):
    """Every rolled-out step-1 or phase step lowers J by at least the fraction of the one before it;
    the step that would not is never rolled out, and the paper's rule alone (0) rolls out more."""
    task = WaypointTask()
    paper = run(task, max_phase_steps=10)
    learner = run(task, max_phase_steps=10, min_J_decrease=fraction)
    J = [cost_of(task, p.w) for p, _ in learner.history]
    assert all(b <= (1.0 - fraction) * a for a, b in zip(J[:-1], J[1:])), np.round(J, 3)
    assert 2 <= len(learner.history) < len(paper.history)
    cfg = CORLConfig(min_J_decrease=fraction)
    with pytest.raises(Exception, match=r"min_J_decrease must be in \[0, 1\)"):
        CORLConfig(min_J_decrease=1.0)
    assert cfg.min_J_decrease == fraction
