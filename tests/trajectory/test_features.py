"""Tests of the squared features (Eq. 7, 9) and equality features (Eq. 6)."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

from corl.trajectory.bspline import BSpline
from corl.trajectory.features import (
    JointLimitFeature,
    TaskSpaceFeature,
    TrajectoryProblem,
    acceleration_feature,
    configuration_feature,
    velocity_feature,
)

SPLINE = BSpline(10, 7, duration=2.0)


def numeric_jacobian(f, w, eps=1e-6):
    cols = [(f(w + eps * e)[0] - f(w - eps * e)[0]) / (2 * eps) for e in np.eye(w.shape[0])]
    return np.stack(cols, axis=1)


def start(seed=0):
    return 0.3 * np.random.default_rng(seed).normal(size=SPLINE.n)


def test_acceleration_feature_is_eq9_on_the_discretized_trajectory():
    w, K = start(1), 25
    v = np.linspace(1.0, 2.0, K - 1)
    phi, A = acceleration_feature(SPLINE, K, weights=v)(w)
    x = SPLINE.positions(w, SPLINE.grid(K))
    dt = 2.0 / K
    expected = np.sqrt(v)[:, None] * (x[2:] - 2 * x[1:-1] + x[:-2]) / dt**2
    np.testing.assert_allclose(phi, expected.reshape(-1), rtol=1e-10, atol=1e-9)
    assert sp.issparse(A)


@pytest.mark.parametrize(
    "make",
    [
        lambda: acceleration_feature(SPLINE, 20, weights=0.5),
        lambda: velocity_feature(SPLINE, 20, weights=np.linspace(0.1, 1, 20)),
        lambda: configuration_feature(SPLINE, 0.0, np.zeros(7)),
        lambda: JointLimitFeature(SPLINE, SPLINE.grid(15), -0.25, 0.3, weight=4.0),
    ],
    ids=["acceleration", "velocity", "configuration", "joint-limits"],
)
def test_feature_jacobians_match_finite_differences(make):
    feature = make()
    w = start(2)
    phi, J = feature(w)
    assert sp.issparse(J) and J.shape == (phi.shape[0], SPLINE.n)
    np.testing.assert_allclose(J.toarray(), numeric_jacobian(feature, w), atol=1e-6)


def test_joint_limits_penalise_only_violations():
    feature = JointLimitFeature(SPLINE, SPLINE.grid(15), -1.0, 1.0)
    phi, J = feature(np.zeros(SPLINE.n))
    assert not phi.any() and J.nnz == 0
    phi, _ = feature(np.full(SPLINE.n, 1.5))
    np.testing.assert_allclose(phi, 0.5)


def test_task_space_feature_jacobian_and_curvature(arm):
    fk, fk_hessian = arm
    w = start(3)
    targets = np.array([[0.3, 0.1, 0.6], [0.2, 0.0, 0.7]])
    with_hessian = TaskSpaceFeature(SPLINE, fk, [0.7, 1.1], targets, fk_hessian=fk_hessian)
    h, J = with_hessian(w)
    x = SPLINE.positions(w, [0.7, 1.1])
    np.testing.assert_allclose(h, np.concatenate([fk(x[0])[0], fk(x[1])[0]]) - targets.reshape(-1), atol=1e-14)
    np.testing.assert_allclose(J.toarray(), numeric_jacobian(with_hessian, w), atol=1e-7)
    # sum_i nu_i d2h_i/dw2 against differences of Jh^T nu, with the analytic and the numeric fk Hessian
    nu = np.random.default_rng(4).normal(size=6)
    grad = lambda v: (with_hessian(v)[1].T @ nu, None)  # noqa: E731
    expected = numeric_jacobian(grad, w)
    for feature in (with_hessian, TaskSpaceFeature(SPLINE, fk, [0.7, 1.1], targets)):
        problem = TrajectoryProblem(SPLINE.n, [acceleration_feature(SPLINE, 20)], [feature])
        C = problem.equality_curvature(w, nu).toarray()
        np.testing.assert_allclose(C, expected, atol=2e-5)


def test_problem_stacks_features_and_its_affine_cost_matches(arm):
    fk, _ = arm
    acc, vel = acceleration_feature(SPLINE, 20), velocity_feature(SPLINE, 20, weights=0.1)
    q0 = np.full(7, 0.1)
    task = TaskSpaceFeature(SPLINE, fk, [1.0], [0.3, 0.1, 0.6])
    problem = TrajectoryProblem(SPLINE.n, [acc, vel], [task, configuration_feature(SPLINE, 0.0, q0)])
    w = start(5)
    r, Jr = problem.residuals(w)
    np.testing.assert_allclose(r, np.concatenate([acc(w)[0], vel(w)[0]]))
    h, Jh = problem.equalities(w)
    np.testing.assert_allclose(h, np.concatenate([SPLINE.positions(w, [0.0])[0] - q0, task(w)[0]]), atol=1e-14)
    np.testing.assert_allclose(Jh.toarray(), numeric_jacobian(problem.equalities, w), atol=1e-7)
    H, c = problem.affine_cost()
    np.testing.assert_allclose(H @ w - c, 2 * Jr.T @ r, rtol=1e-10, atol=1e-8)
    np.testing.assert_allclose(H.toarray(), 2 * (Jr.T @ Jr).toarray(), rtol=1e-10, atol=1e-8)
    assert problem.cost(w) == pytest.approx(r @ r)
    limits = JointLimitFeature(SPLINE, SPLINE.grid(10), -1, 1)
    assert TrajectoryProblem(SPLINE.n, [acc, limits]).affine_cost() is None
