"""PoWER: convergence, budget, ask/tell protocol, failures, weights, reproducibility."""

from __future__ import annotations

import numpy as np
import pytest

from corl.errors import InputError, StateError
from corl.optimizers.power import PoWER, PoWERConfig, power_weights
from blackbox_loop import C2, UNIT2, quadratic, run
from corl.problem import Outcome


def test_converges_on_2d_quadratic_and_stops_at_budget():
    opt = PoWER(UNIT2, [0.8, 0.2], max_evals=200, seed=0)
    X = run(opt, quadratic(C2))
    assert opt.n_evals == 200 and opt.done
    assert np.linalg.norm(opt.best[0] - C2) < 0.05
    assert np.linalg.norm(opt.mean_ - C2) < 0.05
    assert np.all((X >= 0.0) & (X <= 1.0))
    with pytest.raises(StateError):
        opt.ask()


def test_ask_twice_returns_the_same_point():
    opt = PoWER(UNIT2, [0.5, 0.5], seed=1)
    x = opt.ask()
    np.testing.assert_array_equal(opt.ask(), x)
    opt.tell(x, Outcome(True, 0.0))
    assert not np.array_equal(opt.ask(), x)


def test_same_seed_same_sequence_different_seed_differs():
    xa = run(PoWER(UNIT2, [0.8, 0.2], max_evals=40, seed=7), quadratic(C2))
    xb = run(PoWER(UNIT2, [0.8, 0.2], max_evals=40, seed=np.random.default_rng(7)), quadratic(C2))
    xc = run(PoWER(UNIT2, [0.8, 0.2], max_evals=40, seed=8), quadratic(C2))
    np.testing.assert_array_equal(xa, xb)
    assert not np.allclose(xa, xc)


def test_failures_score_failure_return_and_the_search_leaves_the_failing_region():
    c = np.array([0.3, 0.4])
    rollout = quadratic(c, fail_above=0.5)
    opt = PoWER(UNIT2, [0.6, 0.6], max_evals=200, seed=3)  # starts inside the failing region
    X = run(opt, rollout)
    np.testing.assert_array_equal(opt.scores_[~opt.success_], -15.0)
    assert opt.mean_[1] < 0.5
    assert np.mean(X[-50:, 1] > 0.5) < 0.3  # only the tail of the exploration crosses over
    assert np.linalg.norm(opt.best[0] - c) < 0.05
    # a failure rewarded above every return keeps the search in the failing region instead
    lured = PoWER(UNIT2, [0.6, 0.6], max_evals=200, failure_return=1.0, seed=3)
    X = run(lured, rollout)
    assert lured.mean_[1] > 0.5
    assert np.mean(X[-50:, 1] > 0.5) > 0.6


def test_update_is_the_weighted_average_of_the_best_rollouts():
    opt = PoWER(UNIT2, [0.5, 0.5], PoWERConfig(n_best=2, beta=np.log(3.0)), seed=2)
    opt.tell(np.array([0.2, 0.2]), Outcome(True, 1.0))
    opt.tell(np.array([0.8, 0.8]), Outcome(False, None))  # -15: the worst of all
    opt.tell(np.array([0.4, 0.6]), Outcome(True, 0.0))
    # best two: scores 1 and 0, weights 1 and exp(-log 3) = 1/3
    np.testing.assert_allclose(opt.mean_, (1.0 * np.array([0.2, 0.2]) + np.array([0.4, 0.6]) / 3) / (4 / 3))


def test_weights_are_scale_free_and_equal_on_a_plateau():
    s = np.array([-15.0, -1.0, 0.0])
    np.testing.assert_allclose(power_weights(s, 10.0), power_weights(1000.0 * s + 7.0, 10.0))
    np.testing.assert_allclose(power_weights(s, 10.0)[[0, 2]], [np.exp(-10.0), 1.0])
    np.testing.assert_array_equal(power_weights(np.full(4, -15.0), 10.0), np.ones(4))


def test_weights_of_scores_whose_differences_overflow():
    # 1.7e308 - (-1.7e308) is past float64's range; the weights are those of the same scores in any unit
    s = np.array([1.7e308, -1.7e308, 0.0])
    np.testing.assert_allclose(power_weights(s, 10.0), power_weights(np.array([1.0, -1.0, 0.0]), 10.0), rtol=1e-12)


def test_exploration_decays_and_tolerance_stops():
    opt = PoWER(UNIT2, [0.5, 0.5], PoWERConfig(std=0.1, decay=0.5, tol_std=0.01), max_evals=100, seed=4)
    run(opt, quadratic(C2))
    assert opt.n_evals == 4  # 0.1 * 0.5**4 < 0.01
    assert opt.done and opt.stop_reason.value == "converged"
    with pytest.raises(StateError):
        opt.ask()


def test_config_is_validated():
    with pytest.raises(InputError):
        PoWERConfig(n_best=0)
    with pytest.raises(InputError):
        PoWERConfig(std=0.0)
    with pytest.raises(InputError):
        PoWERConfig(decay=1.5)
    with pytest.raises(InputError):
        PoWERConfig(beta=-1.0)
    with pytest.raises(InputError):
        PoWER(UNIT2, [0.5, 1.5])
