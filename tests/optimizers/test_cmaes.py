"""CMAES: convergence, budget, ask/tell protocol, failures, 1-D, reproducibility."""

from __future__ import annotations

import numpy as np
import pytest

from corl.errors import InputError, StateError
from corl.optimizers.cmaes import CMAES, CMAESConfig
from blackbox_loop import C2, UNIT2, quadratic, run
from corl.problem import Bounds, Outcome


def test_converges_on_2d_quadratic_and_stops_at_budget():
    opt = CMAES(UNIT2, [0.8, 0.2], max_evals=200, seed=0)
    run(opt, quadratic(C2))
    assert opt.n_evals == 200 and opt.done and opt.stop_reason.value == "budget"
    x_best, r_best = opt.best
    assert np.linalg.norm(x_best - C2) < 0.05
    assert np.linalg.norm(opt.mean_ - C2) < 0.05
    with pytest.raises(StateError):
        opt.ask()


def test_ask_twice_returns_the_same_point():
    opt = CMAES(UNIT2, [0.5, 0.5], seed=1)
    x = opt.ask()
    np.testing.assert_array_equal(opt.ask(), x)
    opt.tell(x, Outcome(True, 0.0))
    assert not np.array_equal(opt.ask(), x)


def test_population_is_handed_out_one_by_one_and_updated_when_complete():
    opt = CMAES(UNIT2, [0.5, 0.5], CMAESConfig(popsize=5), seed=2)
    rollout = quadratic(C2)
    for _ in range(4):
        x = opt.ask()
        opt.tell(x, rollout(x))
    assert opt.es_.countiter == 0  # one member still out
    x = opt.ask()
    opt.tell(x, rollout(x))
    assert opt.es_.countiter == 1


def test_same_seed_same_sequence_and_global_numpy_state_does_not_matter():
    a = CMAES(UNIT2, [0.8, 0.2], max_evals=40, seed=7)
    b = CMAES(UNIT2, [0.8, 0.2], max_evals=40, seed=np.random.default_rng(7))
    c = CMAES(UNIT2, [0.8, 0.2], max_evals=40, seed=8)
    xa = run(a, quadratic(C2))
    np.random.seed(123)
    rollout = quadratic(C2)
    xb = []
    while not b.done:
        np.random.rand(5)  # other code drawing from numpy's global generator in between
        x = b.ask()
        xb.append(x)
        b.tell(x, rollout(x))
    xc = run(c, quadratic(C2))
    np.testing.assert_array_equal(xa, np.array(xb))
    assert not np.allclose(xa, xc)


def test_failures_score_failure_return_and_the_search_leaves_the_failing_region():
    c = np.array([0.3, 0.4])
    rollout = quadratic(c, fail_above=0.5)
    # starts inside the failing region; with seed 4 the whole first population fails
    opt = CMAES(UNIT2, [0.6, 0.6], max_evals=200, seed=4)
    X = run(opt, rollout)
    assert not np.any(opt.success_[:6])  # a flat first generation did not end the search
    assert opt.n_evals == 200
    assert np.mean(X[-50:, 1] > 0.5) < 0.1  # the late trials stay on the safe side
    assert np.linalg.norm(opt.best[0] - c) < 0.05
    # a failure rewarded above every return pulls the search into the failing region instead
    lured = CMAES(UNIT2, [0.6, 0.6], max_evals=200, failure_return=1.0, seed=4)
    X = run(lured, rollout)
    assert np.mean(X[-50:, 1] > 0.5) > 0.8


def test_flat_fitness_stops_only_when_asked_for():
    always_fails = lambda x: Outcome(False, None)  # noqa: E731
    stopping = CMAES(UNIT2, [0.5, 0.5], CMAESConfig(popsize=6, flat_fitness_stops=True), max_evals=200, seed=0)
    run(stopping, always_fails)
    assert stopping.done and stopping.n_evals < 30  # pycma reads the plateau as convergence
    assert stopping.stop_reason.value == "converged"
    with pytest.raises(StateError):
        stopping.ask()
    patient = CMAES(UNIT2, [0.5, 0.5], CMAESConfig(popsize=6), max_evals=200, seed=0)
    run(patient, always_fails)
    assert patient.n_evals == 200 and patient.best is None


def test_one_dimensional_search_converges():
    bounds = Bounds([-2.0], [3.0])
    opt = CMAES(bounds, [2.5], max_evals=200, seed=4)
    X = run(opt, quadratic(np.array([-1.2])))
    assert X.shape[1] == 1 and opt.done
    assert abs(opt.best[0][0] + 1.2) < 0.05
    assert np.all((X >= -2.0) & (X <= 3.0))


def test_one_dimensional_flat_fitness_keeps_the_step_size_capped():
    # every trial fails: pycma widens the step size; in 1-D pycma 4.4.4 would raise at its cap
    opt = CMAES(Bounds([0.0], [1.0]), [0.5], CMAESConfig(sigma0=0.3), max_evals=200, seed=5)
    largest = 0.0
    while not opt.done:
        x = opt.ask()
        opt.tell(x, Outcome(False, None))
        largest = max(largest, float(opt.es_.stds[0]))
    assert opt.n_evals == 200 and opt.best is None
    assert 0.3 < largest <= 1.0 / 3.0 + 1e-12  # it grew and met the cap
    with pytest.raises(StateError):
        opt.ask()


def test_a_point_that_was_not_asked_is_kept_in_the_data_only():
    opt = CMAES(UNIT2, [0.5, 0.5], CMAESConfig(popsize=4), seed=6)
    x = opt.ask()
    opt.tell(np.array([0.3, 0.7]), Outcome(True, 5.0))  # a demonstration, say
    np.testing.assert_array_equal(opt.ask(), x)  # the member that is out stays pending
    assert opt.best[1] == 5.0
    rollout = quadratic(C2)
    for _ in range(4):
        x = opt.ask()
        opt.tell(x, rollout(x))
    assert opt.es_.countiter == 1 and opt.n_evals == 5


def test_config_is_validated():
    with pytest.raises(InputError):
        CMAESConfig(sigma0=0.0)
    with pytest.raises(InputError):
        CMAESConfig(popsize=1)
    with pytest.raises(InputError):
        CMAESConfig(tolx=-1.0)
    with pytest.raises(InputError):
        CMAES(UNIT2, [1.5, 0.5])
