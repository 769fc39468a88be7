"""GP classification g_S (Eq. 13): Laplace mode with a constant prior mean, prediction, labels."""

import warnings

import numpy as np
import pytest
from scipy import integrate, optimize
from scipy.special import expit

from corl.errors import InputError, StateError
from corl.gp import GPClassifier, SquaredExponential, expected_sigmoid
from corl.optimizers.gpconfig import SYNTHETIC_CLASSIFIER


def _paper_problem(n=30):
    X = np.linspace(-np.pi, np.pi, n)
    return X, (X > -1.5) & (X < 2.5)


def _neg_log_posterior(f, K, y, m0):
    r = f - m0
    return 0.5 * r @ np.linalg.solve(K, r) + np.sum(np.logaddexp(0.0, -y * f))


def test_mode_of_one_point_matches_grid_search():
    gp = GPClassifier(SquaredExponential(0.4, 3.0), prior_mean=-2.0).fit([0.5], [1])
    grid = np.linspace(-10, 10, 200001)
    # -log posterior for one point: (f - m0)^2 / (2 sf^2) + log(1 + exp(-f))
    objective = (grid + 2.0) ** 2 / 18.0 + np.logaddexp(0.0, -grid)
    assert gp.f_hat_[0] == pytest.approx(grid[np.argmin(objective)], abs=2e-4)


def test_mode_of_two_points_matches_scipy_minimizer():
    X, y, m0 = np.array([[0.0], [0.3]]), np.array([1.0, -1.0]), -7.0
    kernel = SquaredExponential(0.4, 10.0)
    gp = GPClassifier(kernel, prior_mean=m0).fit(X, y)
    res = optimize.minimize(_neg_log_posterior, np.full(2, m0), args=(kernel(X), y, m0), method="BFGS", options={"gtol": 1e-10})
    np.testing.assert_allclose(gp.f_hat_, res.x, atol=1e-4)


def test_mode_satisfies_the_fixed_point_equation():
    X, s = _paper_problem()
    gp = SYNTHETIC_CLASSIFIER.build().fit(X, s)
    K = gp.kernel_(gp.X_)
    t = s.astype(float)
    # GPML eq. 3.17 with a mean: f_hat = m0 + K (t - sigma(f_hat))
    np.testing.assert_allclose(gp.f_hat_, -7.0 + K @ (t - expit(gp.f_hat_)), atol=1e-5)
    np.testing.assert_allclose(gp.W_, expit(gp.f_hat_) * expit(-gp.f_hat_), rtol=1e-12)
    # the predictive mean at the training inputs reproduces the mode (Alg. 3.2, line 4)
    np.testing.assert_allclose(gp.predict_latent(X)[0], gp.f_hat_, atol=1e-5)


def test_paper_hyperparameters_converge_without_overflow():
    X, s = _paper_problem()
    with warnings.catch_warnings(), np.errstate(over="raise", invalid="raise", divide="raise"):
        warnings.simplefilter("error")
        gp = GPClassifier(SquaredExponential(0.4, 10.0), prior_mean=-7.0, warm_start=False).fit(X, s)
        mean, var = gp.predict_latent(np.linspace(-6, 6, 201))
        p = gp.predict_proba(np.linspace(-6, 6, 201))
    assert gp.converged_ and gp.n_iter_ < 50
    assert np.all(np.isfinite(gp.f_hat_)) and np.all(np.isfinite(mean)) and np.all(np.isfinite(p))
    assert np.all(gp.f_hat_[s] > 0) and np.all(gp.f_hat_[~s] < 0)
    assert np.all((var > 0) & (var <= 100.0 + 1e-9))


def test_far_from_data_latent_tends_to_prior():
    X, s = _paper_problem()
    gp = SYNTHETIC_CLASSIFIER.build().fit(X, s)
    mean, var = gp.predict_latent(np.array([-20.0, 20.0]))
    np.testing.assert_allclose(mean, -7.0, atol=1e-9)
    np.testing.assert_allclose(var, 100.0, rtol=1e-9)


def test_probability_high_near_successes_and_low_near_failures():
    X, s = _paper_problem()
    gp = SYNTHETIC_CLASSIFIER.build().fit(X, s)
    p = gp.predict_proba(np.array([0.5, 1.0, -3.0, 3.0, 10.0]))
    # with sf = 10 the latent variance stays large, so E[sigma(g)] is far from 0 and 1
    assert np.all(p[:2] > 0.75)
    assert np.all(p[2:4] < 0.25)
    assert p[4] == pytest.approx(expected_sigmoid(-7.0, 100.0)[()])  # far away: the prior
    mean, var = gp.predict_latent(np.array([0.5, -3.0]))
    assert mean[0] > 3.0 and mean[1] < -5.0
    assert var[0] < 20.0 and var[1] < 100.0


def test_zero_data_predicts_the_prior():
    gp = GPClassifier(SquaredExponential(0.4, 10.0), prior_mean=-7.0).fit(np.empty((0, 2)), [])
    mean, var = gp.predict_latent(np.zeros((3, 2)))
    np.testing.assert_allclose(mean, -7.0)
    np.testing.assert_allclose(var, 100.0)
    np.testing.assert_allclose(gp.predict_proba(np.zeros((1, 2))), expected_sigmoid(-7.0, 100.0))
    assert gp.log_marginal_likelihood() == 0.0


@pytest.mark.parametrize("mu, var", [(0.0, 1e-10), (-7.0, 100.0), (2.0, 4.0), (3.7, 0.3), (-1.0, 2.25), (12.0, 9.0), (0.4, 40.0)])
def test_expected_sigmoid_matches_numeric_integral(mu, var):
    sd = np.sqrt(var)
    integrand = lambda f: expit(f) * np.exp(-0.5 * ((f - mu) / sd) ** 2) / (sd * np.sqrt(2 * np.pi))
    lo, hi = mu - 12 * sd, mu + 12 * sd
    points = [0.0] if lo < 0.0 < hi else None
    ref = integrate.quad(integrand, lo, hi, points=points, epsabs=1e-13, epsrel=1e-12, limit=400)[0]
    assert expected_sigmoid(np.array([mu]), np.array([var]))[0] == pytest.approx(ref, abs=1e-7)


def test_laplace_marginal_likelihood_matches_direct_formula():
    X, s = _paper_problem(12)
    gp = GPClassifier(SquaredExponential(0.8, 2.0), prior_mean=-1.0).fit(X, s)
    K = gp.kernel_(X)
    y = np.where(s, 1.0, -1.0)
    f = gp.f_hat_
    # GPML eq. 3.32: -1/2 (f - m)^T K^{-1} (f - m) + log p(y|f) - 1/2 log|I + K W|
    quad = (f + 1.0) @ np.linalg.solve(K + 1e-12 * np.eye(len(f)), f + 1.0)
    expected = -0.5 * quad - np.sum(np.logaddexp(0.0, -y * f)) - 0.5 * np.linalg.slogdet(np.eye(len(f)) + K * gp.W_)[1]
    assert gp.log_marginal_likelihood() == pytest.approx(expected, rel=1e-6)


@pytest.mark.parametrize("lengthscales", [0.8, [0.6, 1.5]])
def test_laplace_marginal_likelihood_gradient_matches_finite_differences(lengthscales):
    rng = np.random.default_rng(7)
    X = rng.uniform(-2, 2, size=(15, 2))
    s = X[:, 0] + 0.5 * X[:, 1] > 0.2
    gp = GPClassifier(SquaredExponential(lengthscales, 2.5), prior_mean=-1.5, tol=1e-13).fit(X, s)
    v0 = gp.kernel_.log_params
    _, grad = gp.log_marginal_likelihood(v0, eval_gradient=True)
    eps = 1e-5
    fd = np.array(
        [
            (gp.log_marginal_likelihood(v0 + eps * e) - gp.log_marginal_likelihood(v0 - eps * e)) / (2 * eps)
            for e in np.eye(v0.size)
        ]
    )
    np.testing.assert_allclose(grad, fd, rtol=1e-4, atol=1e-6)


def test_optimize_hyperparameters_raises_marginal_likelihood():
    X, s = _paper_problem(20)
    gp = GPClassifier(SquaredExponential(0.4, 10.0), prior_mean=-7.0)
    start = gp.fit(X, s).log_marginal_likelihood()
    gp.optimize_hyperparameters(X, s, bounds=[(0.05, 5.0), (0.5, 20.0)])
    assert gp.log_marginal_likelihood() > start
    assert gp.kernel.lengthscales[0] == 0.4  # settings untouched


@pytest.mark.parametrize(
    "labels",
    [np.array([True, False, True]), np.array([1, 0, 1]), np.array([1.0, -1.0, 1.0])],
)
def test_label_encodings_give_the_same_fit(labels):
    X = np.array([0.0, 0.5, 1.0])
    gp = GPClassifier().fit(X, labels)
    np.testing.assert_array_equal(gp.y_, [1.0, -1.0, 1.0])
    ref = GPClassifier().fit(X, [1, -1, 1])
    np.testing.assert_allclose(gp.f_hat_, ref.f_hat_)


@pytest.mark.parametrize("labels", [[0, 2, 1], [-1, 0, 1], [0.5, 1, 0], ["a", "b", "a"], [1, np.nan, 0]])
def test_invalid_labels_raise(labels):
    with pytest.raises(InputError, match="labels"):
        GPClassifier().fit([0.0, 0.5, 1.0], labels)


def test_bad_inputs_and_state():
    with pytest.raises(InputError, match="X contains NaN"):
        GPClassifier().fit([0.0, np.nan], [1, 0])
    with pytest.raises(InputError, match="one per point"):
        GPClassifier().fit([0.0, 1.0], [1, 0, 1])
    with pytest.raises(StateError, match="fit"):
        GPClassifier().predict_latent([0.0])


def test_duplicate_inputs_are_fine():
    X = np.array([0.0, 0.0, 0.0, 1.0, 1.0])
    gp = SYNTHETIC_CLASSIFIER.build().fit(X, [1, 1, 0, 1, 1])
    assert gp.converged_
    p = gp.predict_proba(np.array([0.0, 1.0]))
    assert np.all(np.isfinite(p)) and p[0] < p[1]


def test_warm_start_reaches_the_same_mode_with_fewer_steps():
    X, s = _paper_problem(31)
    gp = SYNTHETIC_CLASSIFIER.build().fit(X[:-1], s[:-1])
    gp.fit(X, s)
    cold = GPClassifier(SquaredExponential(0.4, 10.0), prior_mean=-7.0, warm_start=False).fit(X, s)
    np.testing.assert_allclose(gp.f_hat_, cold.f_hat_, atol=1e-5)
    assert gp.n_iter_ < cold.n_iter_


def test_latent_posterior_only_where_the_mean_is_positive_is_predict_latent_s():
    rng = np.random.default_rng(3)
    X = rng.uniform(-2, 2, size=(40, 2))
    y = np.linalg.norm(X, axis=1) < 1.2
    gp = GPClassifier(SquaredExponential([0.5, 0.7], 4.0), prior_mean=-3.0).fit(X, y)
    Xs = rng.uniform(-3, 3, size=(5000, 2))  # more than one block
    mean, var = gp.predict_latent_positive(Xs)
    full_mean, full_var = gp.predict_latent(Xs)
    pos = full_mean > 0
    assert 0 < np.sum(pos) < len(Xs) // 2
    np.testing.assert_allclose(mean, full_mean, rtol=1e-12, atol=1e-12 * np.max(np.abs(full_mean)))
    np.testing.assert_allclose(var[pos], full_var[pos], rtol=1e-9, atol=1e-12 * float(gp.kernel.signal_std) ** 2)
    assert np.all(np.isnan(var[~pos]))  # not worked out: never read as a variance
    empty = GPClassifier(SquaredExponential(0.5, 4.0), prior_mean=-3.0).fit(np.zeros((0, 2)), np.zeros(0, bool))
    m0, v0 = empty.predict_latent_positive(Xs[:3])
    assert np.all(m0 == -3.0) and np.all(np.isnan(v0))


@pytest.mark.parametrize("m", [1, 2, 3])
def test_latent_mean_on_a_lattice_factorises_the_kernel(m):
    rng = np.random.default_rng(m)
    X = rng.uniform(-2, 2, size=(40, m))
    gp = GPClassifier(SquaredExponential([0.5, 0.7, 0.6][:m], 4.0), prior_mean=-3.0).fit(X, np.linalg.norm(X, axis=1) < 1.2)
    axes = [np.linspace(-3, 3, n) for n in (17, 13, 11)[:m]]
    lattice = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, m)
    full = gp.predict_latent(lattice)[0]
    np.testing.assert_allclose(gp.latent_mean_on_lattice(axes), full, rtol=1e-12, atol=1e-12 * np.max(np.abs(full)))
    with pytest.raises(InputError, match="axes"):
        gp.latent_mean_on_lattice(axes + [axes[0]])
