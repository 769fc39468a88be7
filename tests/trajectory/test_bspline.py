"""Tests of the B-spline reference trajectories (Sec. V-A)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.interpolate import BSpline as ScipyBSpline

from corl.errors import InputError
from corl.trajectory.bspline import BSpline


@pytest.fixture
def spline():
    return BSpline(num_control_points=12, num_joints=3, duration=2.0)


def test_partition_of_unity_and_nonnegativity(spline):
    t = np.random.default_rng(0).uniform(0, 2.0, 50)
    B = spline.basis(np.r_[0.0, t, 2.0]).toarray()
    np.testing.assert_allclose(B.sum(axis=1), 1.0, atol=1e-14)
    assert B.min() >= 0
    assert (np.count_nonzero(B, axis=1) <= spline.degree + 1).all()


def test_clamped_ends_interpolate_first_and_last_control_points(spline):
    w = np.random.default_rng(1).normal(size=spline.n)
    W = spline.control_points(w)
    ends = spline.positions(w, [0.0, 2.0])
    np.testing.assert_allclose(ends, W[[0, -1]], atol=1e-14)


@pytest.mark.parametrize("degree", [2, 3, 5])
def test_derivatives_match_finite_differences_and_scipy(degree):
    spline = BSpline(15, 2, duration=3.0, degree=degree)
    rng = np.random.default_rng(degree)
    w = rng.normal(size=spline.n)
    t = rng.uniform(0.05, 2.95, 20)
    ref = ScipyBSpline(spline.knots, spline.control_points(w), degree)
    for d in range(1, degree + 1):
        eps = 1e-6
        fd = (spline.evaluate(w, t + eps, d - 1) - spline.evaluate(w, t - eps, d - 1)) / (2 * eps)
        exact = spline.evaluate(w, t, d)
        np.testing.assert_allclose(exact, fd, rtol=1e-6, atol=1e-6 * (1 + np.abs(exact).max()))
        np.testing.assert_allclose(exact, ref(t, d), atol=1e-9 * (1 + np.abs(exact).max()))
    assert np.abs(spline.evaluate(w, t, degree + 1)).max() == 0.0


def test_operator_is_time_major_kron(spline):
    w = np.random.default_rng(2).normal(size=spline.n)
    t = np.linspace(0, 2, 9)
    A = spline.operator(t, 1)
    assert A.shape == (9 * 3, spline.n)
    np.testing.assert_allclose((A @ w).reshape(9, 3), spline.velocities(w, t), atol=1e-12)


def test_fit_reproduces_a_spline_exactly(spline):
    w = np.random.default_rng(3).normal(size=spline.n)
    t = np.linspace(0, 2.0, 40)
    np.testing.assert_allclose(spline.fit(t, spline.positions(w, t)), w, atol=1e-10 * np.abs(w).max())


def test_fit_with_too_few_samples_asks_for_more():
    spline = BSpline(12, 1)
    with pytest.raises(InputError, match="samples"):
        spline.fit(np.linspace(0, 0.3, 30), np.zeros((30, 1)))


def test_invalid_settings_and_times_are_rejected(spline):
    with pytest.raises(InputError, match="degree"):
        BSpline(3, 2, degree=3)
    with pytest.raises(InputError, match="duration"):
        BSpline(6, 2, duration=0.0)
    with pytest.raises(InputError, match=r"\[0, T\]"):
        spline.basis([2.5])
    with pytest.raises(InputError, match="expected"):
        spline.control_points(np.zeros(5))
