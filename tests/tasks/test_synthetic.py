import math

import numpy as np
import pytest

from corl.errors import InputError
from corl.problem import Outcome
from corl.tasks.synthetic import SyntheticTask, distance_to_safe


def test_optimum_reading():
    task = SyntheticTask()
    w = np.array([1.0, 0.0])
    r, _ = task.cost_residuals(w)
    out = task.rollout(w)
    assert out.success and out.return_ == pytest.approx(1.0) and r[0] == 0.0
    assert task.theta_of(w)[0] == 0.0


def test_jacobians_match_finite_differences():
    task = SyntheticTask()
    rng = np.random.default_rng(0)
    for _ in range(10):
        w = rng.uniform(-1.5, 1.5, 2)
        theta = rng.uniform(-3, 3, 1)
        for f in (task.cost_residuals, lambda v: task.constraint(v, theta)):
            val, jac = f(w)
            fd = np.array([(f(w + e)[0] - f(w - e)[0]) / 2e-6 for e in np.eye(2) * 1e-6]).T
            np.testing.assert_allclose(jac, fd, rtol=1e-5, atol=1e-6)


def test_success_region_and_distance():
    task = SyntheticTask()
    for theta, ok in [(0.0, True), (2.4, True), (2.6, False), (-1.6, False), (3.1, False)]:
        out = task.rollout(np.array([math.cos(theta), math.sin(theta)]))
        assert out.success is ok
    assert distance_to_safe(3.0) == pytest.approx(0.5)
    assert distance_to_safe(-2.0) == pytest.approx(0.5)
    assert distance_to_safe(0.3) == 0.0


def test_random_starts_are_feasible_and_bad_start_rejected():
    rng = np.random.default_rng(0)
    for _ in range(50):
        w = SyntheticTask.random_start(rng)
        assert SyntheticTask(w).rollout(w).success
        assert np.all(np.abs(w) <= 1.5)
    with pytest.raises(InputError):
        SyntheticTask((0.0, 0.0))


def test_outcome_validation():
    with pytest.raises(InputError, match="finite"):
        Outcome(True, float("inf"))
    with pytest.raises(InputError, match="number"):
        Outcome(True, "lots")
    with pytest.raises(InputError, match="True or False"):
        Outcome("yes", 1.0)
    assert Outcome(False).return_ is None
