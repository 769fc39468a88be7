"""The bring-your-own-task example learns with the public API only."""

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from examples.planar_button import fingertip, make_task  # noqa: E402

from corl.methods import make_method  # noqa: E402


def test_fingertip_jacobian():
    q = np.array([0.2, 0.9, -0.4])
    p, J = fingertip(q)
    fd = np.array([(fingertip(q + e)[0] - fingertip(q - e)[0]) / 2e-6 for e in np.eye(3) * 1e-6]).T
    np.testing.assert_allclose(J, fd, atol=1e-7)


def test_example_task_learns_safely():
    task = make_task()
    demo = task.demonstration()
    assert task.rollout(demo.w).success
    learner = make_method("CORL+PIBU", task, seed=0)  # the task's own method_settings()
    best = learner.run(max_trials=400)
    fails = sum(not o.success for _, o in learner.history)
    J0 = float(np.sum(task.cost_residuals(demo.w)[0] ** 2))
    assert best.return_ > task.rollout(demo.w).return_ + 0.2  # closer to the sweet spot at +2 cm
    assert abs(best.theta[0] - 0.02) < 0.01
    assert best.J < 0.5 * J0
    assert fails <= 4
