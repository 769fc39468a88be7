"""corl.realise: the task's motion problem (the structured opt-in, ``trajectory_problem``) and Eq. 18.

A task that gives ``trajectory_problem(theta)`` is solved on the banded SQP path, one without it on
the augmented Lagrangian; both must find the same trajectory (the problem is the same)."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from examples.planar_button import make_task  # noqa: E402

import corl.learner  # noqa: E402
from corl.errors import InputError  # noqa: E402
from corl.learner import CORL  # noqa: E402
from corl.problem import Outcome  # noqa: E402
from corl.realise import motion_problem, realise  # noqa: E402
from corl.trajectory.features import TrajectoryProblem  # noqa: E402
from corl.trajectory.solver import FunctionProblem, SolverConfig, solve  # noqa: E402


class Unstructured:
    """The same task without ``trajectory_problem``: corl sees only the two callables."""

    def __init__(self, task) -> None:
        self._task = task

    def __getattr__(self, name):
        if name == "trajectory_problem":
            raise AttributeError(name)
        return getattr(self._task, name)


@pytest.fixture(scope="module")
def button():
    task = make_task()
    return task, task.demonstration()


def test_motion_problem_is_the_tasks_own_and_agrees_with_the_callables(button):
    task, demo = button
    structured = motion_problem(task, demo.theta)
    plain = motion_problem(Unstructured(task), demo.theta)
    assert isinstance(structured, TrajectoryProblem) and isinstance(plain, FunctionProblem)
    assert structured.affine_cost() is not None  # the banded Hessian of J: what SQP needs
    w = demo.w + 0.01 * np.random.default_rng(0).standard_normal(demo.w.shape)
    for a, b in zip(structured.residuals(w) + structured.equalities(w), plain.residuals(w) + plain.equalities(w)):
        a, b = (x.toarray() if hasattr(x, "toarray") else np.asarray(x) for x in (a, b))
        np.testing.assert_allclose(a, b, rtol=1e-12, atol=1e-12 * np.abs(b).max())


def test_step_one_on_sqp_finds_the_augmented_lagrangians_step(button):
    task, demo = button
    config = SolverConfig.precise()
    sqp = solve(motion_problem(task, demo.theta), demo.w, radius=0.2, config=config)
    al = solve(motion_problem(Unstructured(task), demo.theta), demo.w, radius=0.2, config=config)
    assert sqp.converged and al.converged
    assert "SQP" in sqp.status and "SQP" not in al.status
    assert sqp.iterations < al.iterations
    # both solve Eq. 8 to max|h| <= 1e-10: the steps agree to far below their length (0.2)
    assert np.linalg.norm(sqp.w - al.w) <= 1e-6 * np.linalg.norm(sqp.w - demo.w)
    assert sqp.cost == pytest.approx(al.cost, rel=1e-8)


def test_eq18_on_sqp_realises_the_same_trajectory(button):
    task, demo = button
    theta = np.array([0.02])
    structured = realise(task, demo.w, demo.theta, theta)
    plain = realise(Unstructured(task), demo.w, demo.theta, theta)
    assert structured.feasible and plain.feasible and structured.pieces == 0
    assert "SQP" in structured.status and "SQP" not in plain.status
    moved = np.linalg.norm(plain.w - demo.w)
    assert moved > 0.01 and np.linalg.norm(structured.w - plain.w) <= 1e-6 * moved
    assert task.theta_of(structured.w) == pytest.approx(theta, abs=1e-8)


def test_the_learner_solves_step_one_by_sqp_for_a_structured_task(button, monkeypatch):
    task, _ = button
    statuses = []

    def recording(*args, **kwargs):
        result = solve(*args, **kwargs)
        statuses.append(result.status)
        return result

    monkeypatch.setattr(corl.learner, "solve", recording)
    learner = CORL(task, lambda *args: None, task.method_settings().corl)
    learner.ask()
    learner.tell(Outcome(True, 0.0))  # the demonstration; step 1 (Eq. 8) follows
    assert learner.ask().step == "optimization"
    assert statuses and all(s.startswith("converged (SQP)") for s in statuses)


def test_a_trajectory_problem_that_is_no_problem_is_named(button):
    task, demo = button

    class Broken(Unstructured):
        def trajectory_problem(self, theta):
            return "not a problem"

    with pytest.raises(InputError, match="trajectory_problem\\(theta\\) returned str"):
        motion_problem(Broken(task), demo.theta)
