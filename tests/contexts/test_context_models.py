"""GPs over (theta, c): the product kernel in closed form, the slice at one context, and a fit
that recovers the length scales of data drawn with known ones."""

import numpy as np
import pytest

from corl.contexts import ContextData, ContextSlice, ContextualModels, joint_bounds
from corl.errors import InputError
from corl.gp import SquaredExponential
from corl.gp.fitting import fit_regression
from corl.problem import Bounds

THETA = Bounds(np.array([-1.0]), np.array([2.0]))
CONTEXT = Bounds(np.array([0.0, -0.5]), np.array([1.0, 0.5]))


def test_the_joint_kernel_is_the_product_of_a_theta_kernel_and_a_context_kernel():
    rng = np.random.default_rng(0)
    lt, lc, sf = np.array([0.3]), np.array([0.2, 0.7]), 1.7
    X, Y = rng.normal(size=(5, 3)), rng.normal(size=(4, 3))
    joint = SquaredExponential(np.concatenate([lt, lc]), sf)(X, Y)
    k_theta = SquaredExponential(lt, sf)(X[:, :1], Y[:, :1])
    k_context = SquaredExponential(lc, 1.0)(X[:, 1:], Y[:, 1:])
    np.testing.assert_allclose(joint, k_theta * k_context, rtol=1e-10, atol=1e-12 * sf ** 2)


def _data(rng, d=40):
    theta = THETA.from_unit(rng.random((d, 1)))
    context = CONTEXT.from_unit(rng.random((d, 2)))
    f = np.sin(3 * theta[:, 0]) + context[:, 0] - context[:, 1] ** 2
    success = theta[:, 0] - 0.5 * context[:, 0] < 1.2
    return ContextData(theta, context, success, np.where(success, f, np.nan))


def test_a_slice_predicts_what_the_joint_model_predicts_at_its_context():
    rng = np.random.default_rng(1)
    prior = _data(rng)
    c = np.array([0.4, 0.1])
    models = ContextualModels(THETA, CONTEXT, prior, c)
    X = np.array([[0.0], [0.5]])
    reg = models.regression(X, np.array([0.3, 1.2]))
    clf = models.classifier(np.vstack([X, [[1.9]]]), np.array([True, True, False]))
    assert isinstance(reg, ContextSlice) and isinstance(clf, ContextSlice)
    T = np.linspace(-1, 2, 7)[:, None]
    J = np.hstack([T, np.tile(c, (7, 1))])
    for got, want in ((reg.predict(T), models.last_regression.predict(J)),
                      (clf.predict_latent(T), models.last_classifier.predict_latent(J))):
        for a, b in zip(got, want):  # same inputs, same model: equal up to rounding of their scale
            np.testing.assert_allclose(a, b, rtol=1e-9, atol=1e-9 * (1.0 + np.abs(b).max()))
    # the acquisitions read theta's length scales and this context's rows only
    assert reg.kernel.lengthscales.shape == (1,) and reg.kernel.context_lengthscales.shape == (2,)
    np.testing.assert_array_equal(clf.X_, np.vstack([X, [[1.9]]]))
    np.testing.assert_array_equal(clf.y_, [1.0, 1.0, -1.0])
    # the joint fit used every trial: this context's and the prior's
    assert len(models.last_classifier.X_) == len(prior) + 3
    axes = [np.linspace(-1, 2, 4)]
    want = clf.predict_latent(axes[0][:, None])[0]
    np.testing.assert_allclose(clf.latent_mean_on_lattice(axes), want, rtol=1e-9, atol=1e-9 * (1.0 + np.abs(want).max()))


@pytest.mark.parametrize("true_lc", [0.15, 0.6])
def test_the_fit_recovers_the_context_length_scale_of_data_drawn_with_it(true_lc):
    """Data drawn from a GP prior with known unit-box length scales (theta 0.3, context true_lc):
    the MAP fit over the joint box finds the context's within a factor 1.6, and tells a short one
    from a long one."""
    rng = np.random.default_rng(3)
    box = joint_bounds(THETA, Bounds(np.array([0.0]), np.array([2.0])))
    U = rng.random((220, 2))
    kernel = SquaredExponential(np.array([0.3, true_lc]), 1.0)
    K = kernel(U) + 1e-8 * np.eye(len(U))
    y = np.linalg.cholesky(K) @ rng.standard_normal(len(U)) + 0.01 * rng.standard_normal(len(U))
    fit = fit_regression(box.from_unit(U), 5.0 + 2.0 * y, box)
    assert fit.fallback == ""
    l_unit = np.exp(fit.log_params[:2])
    assert 1 / 1.6 < l_unit[1] / true_lc < 1.6, l_unit
    assert 1 / 1.6 < l_unit[0] / 0.3 < 1.6, l_unit


def test_context_data_is_checked():
    with pytest.raises(InputError, match="one row per trial"):
        ContextData(np.zeros((2, 1)), np.zeros((3, 1)), [True, False], [1.0, np.nan])
    with pytest.raises(InputError, match="finite return"):
        ContextData(np.zeros((1, 1)), np.zeros((1, 1)), [True], [np.nan])
    d = ContextData.empty(1, 2).add([0.5], [0.1, 0.2], True, 1.0).add([0.7], [0.1, 0.2], False, None)
    assert len(d) == 2 and d.contexts().shape == (1, 2) and np.isnan(d.returns[1])
