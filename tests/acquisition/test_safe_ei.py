"""SEIB (corl.acquisition.safe_ei): EI closed form, the safety gate, the return gate, no stall."""

import numpy as np
import pytest

from corl.acquisition.safe_ei import SEIB, SEIBConfig, expected_improvement
from corl.errors import InputError
from corl.gp import GPClassifier, GPRegression, SquaredExponential


def test_expected_improvement_matches_numerical_integration():
    from scipy import integrate
    from scipy.stats import norm

    for mu, var, thr in [(0.0, 1.0, 0.5), (2.0, 0.25, 1.0), (-1.0, 4.0, 3.0)]:
        sd = np.sqrt(var)
        ref, _ = integrate.quad(lambda r: (r - thr) * norm.pdf(r, mu, sd), thr, mu + 12 * sd)
        got = expected_improvement(np.array([mu]), np.array([var]), thr)[0]
        assert got == pytest.approx(ref, rel=1e-7, abs=1e-12)
    assert np.all(expected_improvement(np.zeros(3), np.zeros(3), 1.0) >= 0.0)  # var floored, never negative


def _models():
    """1-D: successes on [0.3, 0.6] with R rising to the right, failures at 0 and 1."""
    X = np.array([0.0, 0.3, 0.4, 0.5, 0.6, 1.0])[:, None]
    s = np.array([False, True, True, True, True, False])
    r = np.array([np.nan, 0.0, 1.0, 2.0, 3.0, np.nan])
    clf = GPClassifier(SquaredExponential(0.08, 10.0), prior_mean=-7.0).fit(X, s)
    reg = GPRegression(SquaredExponential(0.15, 2.0), 0.01, prior_mean=1.5).fit(X[s], r[s])
    return reg, clf


def test_value_is_zero_wherever_success_is_unlikely():
    reg, clf = _models()
    acq = SEIB(reg, clf, best_return=3.0, scale=1.1)
    grid = np.linspace(0, 1, 1001)[:, None]
    parts = acq.parts(grid)
    assert np.all(parts["value"][parts["proba"] < acq.config.p_band] == 0.0)
    assert np.any(parts["value"] > 0)


def test_boundary_is_explored_only_where_the_return_may_improve():
    reg, clf = _models()
    acq = SEIB(reg, clf, best_return=3.0, scale=1.1, config=SEIBConfig(boundary_weight=1.0))
    grid = np.linspace(0, 1, 2001)[:, None]
    parts = acq.parts(grid)
    band = parts["band"]
    left, right = band & (grid[:, 0] < 0.45), band & (grid[:, 0] > 0.45)
    assert np.any(left) and np.any(right)  # the model has a boundary on both sides
    assert np.all(parts["value"][left] < 1e-6)  # low returns on the left: that edge is not mapped
    assert np.max(parts["value"][right]) > 0.05  # rising returns on the right: its edge is
    assert 0.45 < grid[np.argmax(parts["value"]), 0] < 0.9


def test_does_not_stall_beside_the_best_point():
    reg, clf = _models()
    acq = SEIB(reg, clf, best_return=3.0, scale=1.1)
    grid = np.linspace(0, 1, 2001)[:, None]
    values = acq(grid)
    at_best = acq(np.array([[0.6]]))[0]
    assert at_best < 0.01 * values.max()  # the margin xi leaves nothing to gain at the best point


def test_without_a_return_model_only_the_boundary_acts():
    _, clf = _models()
    acq = SEIB(None, clf, best_return=0.0, scale=1.0)
    parts = acq.parts(np.linspace(0, 1, 501)[:, None])
    assert np.all(parts["value"][parts["inner"]] == 0.0)
    assert np.all(parts["value"][~parts["band"]] == 0.0)


def test_bad_settings_are_refused():
    with pytest.raises(InputError, match="p_band"):
        SEIBConfig(p_band=0.8, p_inner=0.7)
    reg, clf = _models()
    with pytest.raises(InputError, match="scale"):
        SEIB(reg, clf, 1.0, scale=0.0)
