"""MAP hyperparameters of g_R and g_S (corl.gp.fitting): recovery, units, fallbacks, warm starts."""

import warnings

import numpy as np
import pytest

from corl.errors import InputError
from corl.gp import GPRegression, SquaredExponential
from corl.gp.fitting import ClassifierPriors, RegressionPriors, fit_classifier, fit_regression
from corl.optimizers.gpconfig import SYNTHETIC_CLASSIFIER, SYNTHETIC_REGRESSION, ModelFitter
from corl.problem import Bounds

BOX = Bounds(np.array([-2.0, 0.0]), np.array([2.0, 10.0]))  # widths 4 and 10: units differ per axis


def _gp_sample(lengthscales, d, seed):
    """Inputs (d, 2) in BOX and one draw of a GP with unit-box length scales at them."""
    rng = np.random.default_rng(seed)
    U = rng.random((d, 2))
    K = SquaredExponential(np.asarray(lengthscales), 1.0)(U) + 1e-8 * np.eye(d)
    f = np.linalg.cholesky(K) @ rng.normal(size=d)
    return BOX.from_unit(U), f, rng


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_regression_recovers_known_length_scales_in_unit_box_units(seed):
    X, f, rng = _gp_sample([0.15, 0.4], 70, seed)
    y = 5.0 + 3.0 * f + 0.01 * rng.normal(size=f.size)  # shifted and scaled: standardisation undoes it
    res = fit_regression(X, y, BOX)
    assert res.fallback == ""
    l_unit = np.exp(res.log_params[:2])
    np.testing.assert_allclose(l_unit, [0.15, 0.4], rtol=0.3)
    # the model in theta units carries l_unit * width
    np.testing.assert_allclose(res.model.kernel.lengthscales, l_unit * BOX.width, rtol=1e-12)


def test_fitted_model_in_theta_units_equals_the_unit_box_model():
    X, f, _ = _gp_sample([0.2, 0.3], 30, 5)
    y = 100.0 + 20.0 * f
    res = fit_regression(X, y, BOX)
    v, scale = res.log_params, res.extra["scale"]
    unit = GPRegression(SquaredExponential(np.exp(v[:2]), np.exp(v[2])), np.exp(v[3]))
    unit.fit(BOX.to_unit(X), (y - y.mean()) / scale)
    Xs = BOX.from_unit(np.random.default_rng(1).random((20, 2)))
    mean, var = res.model.predict(Xs)
    mu_u, var_u = unit.predict(BOX.to_unit(Xs))
    np.testing.assert_allclose(mean, y.mean() + scale * mu_u, rtol=1e-9, atol=1e-9 * scale)
    np.testing.assert_allclose(var, scale**2 * var_u, rtol=1e-7, atol=1e-12 * scale**2)


def test_classifier_length_scale_follows_the_data():
    fitted = []
    for l in (0.08, 0.5):
        X, f, _ = _gp_sample([l, l], 80, 3)
        res = fit_classifier(X, f > 0, BOX, prior_mean=0.0)
        assert res.fallback == ""
        fitted.append(np.exp(res.log_params[:2]).mean())
    assert fitted[0] < 0.6 * fitted[1]  # a wiggly boundary gives clearly shorter length scales


def test_two_points_fall_back_to_prior_medians_and_stay_finite():
    X = BOX.from_unit(np.array([[0.2, 0.3], [0.4, 0.5]]))
    res = fit_regression(X, np.array([1.0, 3.0]), BOX)
    assert "2 successful point(s)" in res.fallback
    pri = RegressionPriors()
    np.testing.assert_allclose(np.exp(res.log_params), [pri.lengthscale.median] * 2 + [pri.signal_std.median,
                                                                                        pri.noise_std.median])
    mean, var = res.model.predict(BOX.from_unit(np.random.default_rng(0).random((10, 2))))
    assert np.all(np.isfinite(mean)) and np.all(np.isfinite(var)) and np.all(var > 0)


def test_one_point_and_equal_returns_fall_back():
    X = BOX.from_unit(np.array([[0.5, 0.5]]))
    res = fit_regression(X, np.array([7.0]), BOX)
    assert res.fallback and np.isfinite(res.model.predict(X)[0]).all()
    X3 = BOX.from_unit(np.array([[0.1, 0.1], [0.5, 0.5], [0.9, 0.2]]))
    res = fit_regression(X3, np.full(3, 2.5), BOX)
    assert res.fallback == "all returns equal"
    assert np.all(np.isfinite(res.model.predict(X3)[1]))


@pytest.mark.parametrize("label", [True, False])
def test_all_equal_labels_fall_back_and_stay_finite(label):
    X = BOX.from_unit(np.random.default_rng(2).random((6, 2)))
    res = fit_classifier(X, np.full(6, label), BOX, prior_mean=-7.0)
    assert res.fallback == "all outcomes equal"
    pri = ClassifierPriors()
    np.testing.assert_allclose(np.exp(res.log_params), [pri.lengthscale.median] * 2 + [pri.signal_std.median])
    p = res.model.predict_proba(BOX.from_unit(np.random.default_rng(3).random((50, 2))))
    assert np.all(np.isfinite(p)) and np.all((p >= 0) & (p <= 1))


def test_fit_stays_within_the_prior_bounds_on_duplicates():
    X = BOX.from_unit(np.array([[0.5, 0.5]] * 4 + [[0.2, 0.8], [0.8, 0.2]]))
    y = np.array([1.0, 1.1, 0.9, 1.0, 0.0, 2.0])  # duplicates with different returns: noise
    res = fit_regression(X, y, BOX)
    pri = RegressionPriors()
    lo = np.log([pri.lengthscale.low] * 2 + [pri.signal_std.low, pri.noise_std.low])
    hi = np.log([pri.lengthscale.high] * 2 + [pri.signal_std.high, pri.noise_std.high])
    assert np.all(res.log_params >= lo - 1e-9) and np.all(res.log_params <= hi + 1e-9)
    assert np.all(np.isfinite(res.model.predict(X)[0]))


def test_warm_start_reaches_the_same_optimum():
    X, f, _ = _gp_sample([0.2, 0.3], 50, 4)
    cold = fit_regression(X, f, BOX, RegressionPriors(max_iter=200))
    warm = fit_regression(X, f, BOX, RegressionPriors(max_iter=5), warm=cold.log_params)
    np.testing.assert_allclose(warm.log_params, cold.log_params, atol=0.05)


def test_fixed_configs_are_untouched_by_the_fitter():
    rng = np.random.default_rng(0)
    X = rng.uniform(-1, 1, (12, 2))
    y, s = np.sin(X[:, 0]), X[:, 1] < 0.3
    fitter = ModelFitter(SYNTHETIC_REGRESSION, SYNTHETIC_CLASSIFIER, Bounds(-np.ones(2), np.ones(2)))
    Xs = rng.uniform(-1, 1, (5, 2))
    np.testing.assert_array_equal(fitter.regression(X, y).predict(Xs)[0],
                                  SYNTHETIC_REGRESSION.build().fit(X, y).predict(Xs)[0])
    np.testing.assert_array_equal(fitter.classifier(X, s).predict_proba(Xs),
                                  SYNTHETIC_CLASSIFIER.build().fit(X, s).predict_proba(Xs))


def test_regression_fits_returns_far_from_zero_with_a_modest_spread():
    # returns about 1e155 whose spread is 1e-8 of that: y^2 overflows, the fitted GP does not (the
    # refusal below is about the spread, which the GP's variance squares, not about the magnitude)
    X, f, _ = _gp_sample([0.2, 0.3], 12, 0)
    spread = 1e147
    big = fit_regression(X, 1e155 + spread * f, BOX)
    small = fit_regression(X, spread * f, BOX)  # the same data, shifted to where nothing overflows
    Xs = BOX.from_unit(np.random.default_rng(1).random((20, 2)))
    mu_big, var_big = big.model.predict(Xs)
    mu_small, var_small = small.model.predict(Xs)
    # 1e155 is held to 2e139 (float64's eps): 1e-7 of the spread; the fits agree to 1e-5 of it
    np.testing.assert_allclose(mu_big - 1e155, mu_small, rtol=0, atol=1e-5 * spread)
    np.testing.assert_allclose(var_big, var_small, rtol=1e-5)
    assert big.extra["scale"] == pytest.approx(small.extra["scale"], rel=1e-6)


def test_regression_refuses_returns_a_gp_cannot_hold_in_their_units():
    X, f, _ = _gp_sample([0.2, 0.3], 6, 0)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # refused in one line, without an overflow on the way
        for y in (1e200 * f, np.full(6, 1.7e308)):
            with pytest.raises(InputError, match="divide them by a constant"):
                fit_regression(X, y, BOX)  # sf ~ 1e200: its square is past float64's 1.8e308
