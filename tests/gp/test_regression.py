"""GP regression g_R (Eq. 11-12): closed forms, marginal likelihood and its gradient, edge cases."""

import numpy as np
import pytest
from scipy.stats import multivariate_normal

from corl.errors import InputError, StateError
from corl.gp import GPRegression, SquaredExponential
from corl.optimizers.gpconfig import SYNTHETIC_REGRESSION


def _problem(seed=0, d=8, m=2):
    rng = np.random.default_rng(seed)
    X = rng.uniform(-1, 1, size=(d, m))
    y = np.sin(3 * X[:, 0]) + 0.5 * X[:, -1] + 0.05 * rng.normal(size=d)
    Xs = rng.uniform(-1.5, 1.5, size=(5, m))
    return X, y, Xs


def test_posterior_matches_direct_formula_with_prior_mean():
    X, y, Xs = _problem()
    kernel = SquaredExponential([0.6, 1.2], 1.5)
    gp = GPRegression(kernel, noise_std=0.2, prior_mean=2.0).fit(X, y)
    mean, var = gp.predict(Xs)

    Kinv = np.linalg.inv(kernel(X) + 0.04 * np.eye(len(y)))
    ks = kernel(X, Xs)
    np.testing.assert_allclose(mean, 2.0 + ks.T @ Kinv @ (y - 2.0), rtol=1e-10)  # Eq. 11
    np.testing.assert_allclose(var, kernel.diag(Xs) - np.sum(ks * (Kinv @ ks), axis=0), rtol=1e-8)  # Eq. 12

    _, var_noisy = gp.predict(Xs, include_noise=True)
    np.testing.assert_allclose(var_noisy - var, 0.04, rtol=1e-10)


def test_large_test_sets_are_predicted_in_blocks_consistently():
    rng = np.random.default_rng(8)
    X = rng.uniform(-3, 3, size=(300, 1))
    y = np.cos(X[:, 0])
    Xs = rng.uniform(-4, 4, size=(700, 1))  # several blocks of 32768 // 300 = 109 points
    kernel = SquaredExponential(0.4, 2.0)
    gp = GPRegression(kernel, noise_std=0.3, prior_mean=0.5).fit(X, y)
    mean, var = gp.predict(Xs)
    Ky = kernel(X) + 0.09 * np.eye(300)
    ks = kernel(X, Xs)
    np.testing.assert_allclose(mean, 0.5 + ks.T @ np.linalg.solve(Ky, y - 0.5), atol=1e-8)
    np.testing.assert_allclose(var, 4.0 - np.sum(ks * np.linalg.solve(Ky, ks), axis=0), atol=1e-8)


def test_log_marginal_likelihood_matches_gaussian_logpdf():
    X, y, _ = _problem(1)
    kernel = SquaredExponential(0.8, 1.2)
    gp = GPRegression(kernel, noise_std=0.3, prior_mean=-0.5).fit(X, y)
    expected = multivariate_normal(np.full(len(y), -0.5), kernel(X) + 0.09 * np.eye(len(y))).logpdf(y)
    assert gp.log_marginal_likelihood() == pytest.approx(expected, rel=1e-10)


@pytest.mark.parametrize("lengthscales", [0.7, [0.5, 1.3]])
def test_log_marginal_likelihood_gradient_matches_finite_differences(lengthscales):
    X, y, _ = _problem(2)
    gp = GPRegression(SquaredExponential(lengthscales, 1.1), noise_std=0.25, prior_mean=0.3).fit(X, y)
    v0 = gp.log_params_
    _, grad = gp.log_marginal_likelihood(v0, eval_gradient=True)
    eps = 1e-6
    fd = np.array(
        [
            (gp.log_marginal_likelihood(v0 + eps * e) - gp.log_marginal_likelihood(v0 - eps * e)) / (2 * eps)
            for e in np.eye(v0.size)
        ]
    )
    np.testing.assert_allclose(grad, fd, rtol=1e-5, atol=1e-7)


def test_zero_data_predicts_the_prior():
    gp = GPRegression(SquaredExponential(0.4, 10.0), noise_std=0.11, prior_mean=1.5).fit(np.empty((0, 2)), [])
    mean, var = gp.predict(np.zeros((3, 2)))
    np.testing.assert_allclose(mean, 1.5)
    np.testing.assert_allclose(var, 100.0)
    assert gp.log_marginal_likelihood() == 0.0


def test_far_from_data_reverts_to_prior():
    X, y, _ = _problem(3, m=1)
    gp = SYNTHETIC_REGRESSION.build().fit(X, y)
    mean, var = gp.predict(np.array([[50.0]]))
    assert mean[0] == pytest.approx(0.0, abs=1e-12)
    assert var[0] == pytest.approx(100.0)


def test_duplicate_inputs_with_tiny_noise_use_jitter_and_average_targets():
    X = np.array([0.0, 0.0, 0.0, 1.0, 1.0])
    y = np.array([1.0, 1.2, 1.4, -1.0, -1.0])
    gp = GPRegression(SquaredExponential(0.4, 10.0), noise_std=1e-9).fit(X, y)
    assert gp.jitter_ > 0.0
    mean, var = gp.predict(np.array([0.0, 1.0]))
    assert np.all(np.isfinite(mean)) and np.all(var > 0)
    np.testing.assert_allclose(mean, [1.2, -1.0], atol=0.02)


def test_duplicate_inputs_with_paper_noise_shrink_variance():
    X = np.array([0.3] * 10)
    y = np.full(10, 2.0)
    gp = SYNTHETIC_REGRESSION.build().fit(X, y)
    mean, var = gp.predict(np.array([0.3]))
    # ten observations of the same point: the posterior variance is about sigma^2 / 10
    assert var[0] == pytest.approx(0.11**2 / 10, rel=0.01)
    assert mean[0] == pytest.approx(2.0, abs=1e-3)


def test_one_dimensional_inputs_are_read_as_columns():
    X, y, _ = _problem(4, m=1)
    a = GPRegression().fit(X[:, 0], y).predict(np.linspace(-1, 1, 7))
    b = GPRegression().fit(X, y).predict(np.linspace(-1, 1, 7)[:, None])
    np.testing.assert_allclose(a, b)


@pytest.mark.parametrize(
    "X, y, pattern",
    [
        (np.array([[0.0], [np.nan]]), [1.0, 2.0], "X contains NaN"),
        (np.array([[0.0], [1.0]]), [1.0, np.inf], "y contains NaN or infinite"),
        (np.array([[0.0], [1.0]]), [1.0, 2.0, 3.0], "one per point"),
    ],
)
def test_bad_data_raises(X, y, pattern):
    with pytest.raises(InputError, match=pattern):
        GPRegression().fit(X, y)


def test_bad_settings_and_state():
    with pytest.raises(InputError, match="noise_std"):
        GPRegression(noise_std=0.0)
    with pytest.raises(InputError, match="prior_mean"):
        GPRegression(prior_mean=np.nan)
    with pytest.raises(StateError, match="fit"):
        GPRegression().predict(np.zeros((1, 1)))
    gp = GPRegression().fit(np.zeros((2, 1)), [0.0, 1.0])
    with pytest.raises(InputError, match="Xs"):
        gp.predict(np.array([[np.inf]]))


def test_optimize_hyperparameters_raises_marginal_likelihood():
    rng = np.random.default_rng(5)
    X = rng.uniform(-3, 3, size=(25, 1))
    y = np.sin(X[:, 0]) + 0.1 * rng.normal(size=25)
    gp = GPRegression(SquaredExponential(0.4, 10.0), noise_std=0.5)
    start = gp.fit(X, y).log_marginal_likelihood()
    gp.optimize_hyperparameters(X, y, n_restarts=2, seed=0)
    assert gp.log_marginal_likelihood() > start + 5.0
    assert 0.03 < gp.noise_std_ < 0.3  # the true noise is 0.1
    assert gp.kernel.signal_std == 10.0  # the settings are untouched
    # the optimum is interior, so the gradient vanishes there
    _, grad = gp.log_marginal_likelihood(eval_gradient=True)
    np.testing.assert_allclose(grad, 0.0, atol=1e-2)
