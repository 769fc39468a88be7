"""g_S follows a safe set far thinner than its default length-scale prior (issue 25, item 2)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from corl.gp import fitting
from corl.gp.fitting import ClassifierPriors, HyperPrior, fit_classifier, thin_set_prior
from corl.problem import Bounds

UNIT2 = Bounds(np.zeros(2), np.ones(2))
DEFAULT = ClassifierPriors().lengthscale


def _start_and_failures(radius: float, n: int, centre=(0.3, 0.3)):
    """The start (a success) and ``n`` failures on a circle of ``radius`` around it, in the unit square."""
    angles = np.linspace(0.0, 2.0 * np.pi, n, endpoint=False) + 0.3
    X = np.vstack([centre, np.asarray(centre) + radius * np.c_[np.cos(angles), np.sin(angles)]])
    return X, np.r_[True, [False] * n]


def test_the_prior_is_unchanged_without_a_failure_or_for_successes_spread_wider_than_it():
    X, y = _start_and_failures(0.05, 3)
    assert thin_set_prior(X[:1], np.ones(1), DEFAULT) is DEFAULT  # no failure: nothing says thin
    rng = np.random.default_rng(0)
    wide = np.vstack([rng.uniform(0.2, 0.8, (12, 2)), [[0.95, 0.95]]])  # successes across 0.6 of the box
    labels = np.r_[np.ones(12), -1.0]
    assert thin_set_prior(wide, labels, DEFAULT) is DEFAULT


def test_the_thin_median_is_the_closest_failure_or_the_successes_spread_by_hand():
    X, _ = _start_and_failures(0.04, 3)
    y = np.r_[1.0, -1.0, -1.0, -1.0]
    got = thin_set_prior(X, y, DEFAULT)  # one success: no spread, the failures all 0.04 away
    assert got.median == pytest.approx(fitting.THIN_PER_FAILURE * 0.04, rel=1e-9)
    assert got.low == pytest.approx(min(DEFAULT.low, got.median / 3.0), rel=1e-9)
    assert (got.spread, got.high) == (DEFAULT.spread, DEFAULT.high)
    # four successes spread across a strip 0.04 wide, a failure 0.02 past its edge: the spread decides
    strip = np.array([[0.5, 0.5], [0.52, 0.52], [0.54, 0.5], [0.52, 0.48], [0.52, 0.56]])
    labels = np.array([1.0, 1.0, 1.0, 1.0, -1.0])
    ok = strip[:4]
    s_min = np.linalg.svd(ok - ok.mean(axis=0), compute_uv=False)[-1] / 2.0  # sqrt of 4 successes
    assert fitting.THIN_PER_SPREAD * s_min > fitting.THIN_PER_FAILURE * 0.04  # the branch under test
    assert thin_set_prior(strip, labels, DEFAULT).median == pytest.approx(fitting.THIN_PER_SPREAD * s_min, rel=1e-9)
    tight = np.array([[0.5, 0.5], [0.5 + 1e-4, 0.5]])  # a failure closer than the floor allows
    assert thin_set_prior(tight, np.array([1.0, -1.0]), DEFAULT).median == fitting.THIN_FLOOR


def _band_radius(model, centre=(0.3, 0.3), angle=1.5):
    """How far from ``centre``, between the failures, g_S's success probability stays >= 0.55."""
    d = np.linspace(0.0, 0.2, 4001)
    p = model.predict_proba(np.asarray(centre) + d[:, None] * np.array([np.cos(angle), np.sin(angle)]))
    return float(d[np.argmax(p < 0.55)]) if np.any(p < 0.55) else 0.2, float(p[0])


def test_failures_close_around_the_start_no_longer_make_it_a_fluke():
    X, s = _start_and_failures(0.02, 6)  # a safe set thinner than 0.02 around a known-safe start
    default = fit_classifier(X, s, UNIT2, -7.0, replace(ClassifierPriors(), thin=False)).model
    thin = fit_classifier(X, s, UNIT2, -7.0, ClassifierPriors()).model
    radius_default, p_start_default = _band_radius(default)
    radius, p_start = _band_radius(thin)
    assert p_start_default < 0.5  # the default prior explains the start as a lucky success ...
    assert p_start > 0.7 and 0.0 < radius < 0.02  # ... the thin one keeps it, and its band lies inside the failures


def test_on_a_wide_safe_set_with_its_edge_mapped_nothing_says_thin():
    rng = np.random.default_rng(3)
    ok = 0.5 + 0.12 * rng.standard_normal((10, 2))  # a wide safe set around (0.5, 0.5), edge mapped:
    bad = np.array([[0.5, 0.86], [0.87, 0.5], [0.5, 0.13]])  # failures just past it
    X = np.vstack([ok, bad])
    s = np.r_[np.ones(10, bool), np.zeros(3, bool)]
    with_rule = fit_classifier(X, s, UNIT2, -7.0, ClassifierPriors())
    without = fit_classifier(X, s, UNIT2, -7.0, replace(ClassifierPriors(), thin=False))
    np.testing.assert_array_equal(with_rule.log_params, without.log_params)


def _strip_rollout(theta):
    x, y = float(theta[0]), float(theta[1])
    return (abs(y - 0.3 - 0.2 * x) < 0.006, 0.4 * x + y)  # a strip 1.2 % of the box thick, 1.2 % of its area


def test_on_a_thin_strip_corl_fails_less_and_finds_as_much():
    import corl

    box = corl.Bounds([0.0, 0.0], [1.0, 1.0])
    base = corl.OptimizerSettings.for_box(box, fitted=True)
    runs = {}
    for thin in (True, False):
        classifier = replace(base.classifier, priors=replace(base.classifier.priors, thin=thin))
        results = [corl.optimize(_strip_rollout, box, [0.2, 0.34], settings=replace(base, classifier=classifier),
                                 budget=20, seed=seed) for seed in range(3)]
        runs[thin] = (np.mean([r.failures for r in results]), np.mean([r.return_ for r in results]))
    assert runs[True][0] <= 0.6 * runs[False][0], runs  # fewer failures per run (2 against 6 when written) ...
    assert runs[True][1] >= runs[False][1], runs  # ... and a best return at least as high


def _cluster_and_failures(n_ok: int):
    """``n_ok`` successes within 0.004 of (0.3, 0.3) and six failures 0.02 around them (unit square)."""
    rng = np.random.default_rng(5)
    ok = 0.3 + 0.004 * rng.uniform(-1.0, 1.0, (n_ok, 2))
    X, s = _start_and_failures(0.02, 6)
    return np.vstack([ok, X[1:]]), np.r_[np.ones(n_ok, bool), s[1:]]


def test_past_two_successes_the_data_decide_between_the_thin_and_the_wide_fit(monkeypatch):
    X, s = _cluster_and_failures(4)  # past THIN_EARLY: the two fits are weighed
    kept = np.exp(fit_classifier(X, s, UNIT2, -7.0, ClassifierPriors()).log_params[:2])
    assert np.all(kept < DEFAULT.low)  # below the wide prior's bound: the thin fit won the weighing
    monkeypatch.setattr(fitting, "THIN_ODDS", np.inf)  # a thin set never favoured enough
    wide = np.exp(fit_classifier(X, s, UNIT2, -7.0, ClassifierPriors()).log_params[:2])
    assert np.all(wide >= DEFAULT.low)
    X2, s2 = _cluster_and_failures(2)  # at most THIN_EARLY successes: the thin fit, whatever the odds
    early = np.exp(fit_classifier(X2, s2, UNIT2, -7.0, ClassifierPriors()).log_params[:2])
    assert np.all(early < DEFAULT.low)


def test_corl_seeds_seib_s_band_from_five_dimensions_only():
    from corl.acquisition.maximize import MaximizerConfig
    from corl.optimizers.safe import BAND_SEEDS_FROM_DIM, SafeBOOptimizer

    for m in (BAND_SEEDS_FROM_DIM - 1, BAND_SEEDS_FROM_DIM):
        opt = SafeBOOptimizer(Bounds(np.zeros(m), np.ones(m)), max_evals=5)
        want = 0 if m < BAND_SEEDS_FROM_DIM else MaximizerConfig().boundary_pairs
        assert opt._maximizer.boundary_pairs == want
