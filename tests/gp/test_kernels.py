"""Squared exponential kernel (Eq. 16): values, shapes, ARD scaling and hyperparameter gradients."""

import numpy as np
import pytest

from corl.errors import InputError
from corl.gp import SquaredExponential


def _fd_gradient(kernel, X, eps=1e-6):
    v0 = kernel.log_params
    out = []
    for j in range(v0.size):
        e = np.zeros_like(v0)
        e[j] = eps
        out.append((kernel.with_log_params(v0 + e)(X) - kernel.with_log_params(v0 - e)(X)) / (2 * eps))
    return np.array(out)


def test_matches_closed_form_and_is_symmetric():
    rng = np.random.default_rng(0)
    X = rng.normal(size=(7, 2))
    k = SquaredExponential([0.5, 2.0], 3.0)
    K = k(X)
    diff = (X[:, None, :] - X[None, :, :]) / np.array([0.5, 2.0])
    expected = 9.0 * np.exp(-0.5 * np.sum(diff**2, axis=2))  # Eq. 16
    np.testing.assert_allclose(K, expected, rtol=1e-12, atol=1e-14)
    np.testing.assert_array_equal(K, K.T)
    np.testing.assert_allclose(k.diag(X), np.diag(K))
    assert np.all(np.linalg.eigvalsh(K) > -1e-10)


def test_cross_covariance_shape_and_consistency():
    rng = np.random.default_rng(1)
    X, Y = rng.normal(size=(5, 3)), rng.normal(size=(4, 3))
    k = SquaredExponential(0.7, 1.3)
    KXY = k(X, Y)
    assert KXY.shape == (5, 4)
    np.testing.assert_allclose(KXY, k(np.vstack([X, Y]))[:5, 5:], rtol=1e-12)
    np.testing.assert_allclose(k(Y, X), KXY.T, rtol=1e-12)
    assert k(np.empty((0, 3)), Y).shape == (0, 4)


def test_ard_equals_isotropic_kernel_on_rescaled_inputs():
    rng = np.random.default_rng(2)
    X = rng.normal(size=(6, 2))
    l = np.array([0.3, 4.0])
    ard = SquaredExponential(l, 2.0)
    unit = SquaredExponential(1.0, 2.0)
    np.testing.assert_allclose(ard(X), unit(X / l), rtol=1e-12)
    # a very long length scale makes the kernel ignore that coordinate
    long = SquaredExponential([0.3, 1e8], 2.0)
    X2 = X.copy()
    X2[:, 1] = rng.normal(size=6)
    np.testing.assert_allclose(long(X), long(X2), rtol=1e-9)


@pytest.mark.parametrize("lengthscales", [0.6, [0.4, 1.5]])
def test_gradient_matches_finite_differences(lengthscales):
    rng = np.random.default_rng(3)
    X = rng.normal(size=(6, 2))
    k = SquaredExponential(lengthscales, 1.7)
    K, dK = k.gradient(X)
    np.testing.assert_allclose(K, k(X), rtol=1e-12)
    assert dK.shape == (k.n_params, 6, 6)
    np.testing.assert_allclose(dK, _fd_gradient(k, X), rtol=1e-6, atol=1e-8)


def test_log_params_round_trip():
    k = SquaredExponential([0.4, 2.0], 10.0)
    np.testing.assert_allclose(k.log_params, np.log([0.4, 2.0, 10.0]))
    k2 = k.with_log_params(np.log([1.0, 3.0, 5.0]))
    np.testing.assert_allclose(k2.lengthscales, [1.0, 3.0])
    assert k2.signal_std == pytest.approx(5.0)
    np.testing.assert_allclose(k.lengthscales, [0.4, 2.0])  # the original is unchanged
    with pytest.raises(InputError, match="expected \\(3,\\)"):
        k.with_log_params([0.0, 1.0])


@pytest.mark.parametrize(
    "kwargs, pattern",
    [
        ({"lengthscales": -1.0}, "lengthscales"),
        ({"lengthscales": [0.5, 0.0]}, "lengthscales"),
        ({"lengthscales": np.nan}, "lengthscales"),
        ({"signal_std": 0.0}, "signal_std"),
        ({"signal_std": np.inf}, "signal_std"),
    ],
)
def test_invalid_hyperparameters_raise(kwargs, pattern):
    with pytest.raises(InputError, match=pattern):
        SquaredExponential(**kwargs)


def test_input_validation():
    k = SquaredExponential([0.5, 0.5], 1.0)
    with pytest.raises(InputError, match="expected"):
        k(np.zeros((3, 3)))
    with pytest.raises(InputError, match="NaN"):
        k(np.array([[0.0, np.nan]]))
    iso = SquaredExponential(0.5, 1.0)
    with pytest.raises(InputError, match="columns"):
        iso(np.zeros((2, 1)), np.zeros((2, 2)))
    # a 1-D array is read as points in one dimension
    np.testing.assert_allclose(iso(np.array([0.0, 1.0])), iso(np.array([[0.0], [1.0]])))
