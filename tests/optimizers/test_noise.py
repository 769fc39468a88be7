"""Noisy returns and a success sensor that errs (issue "A real robot is noisy"): the learner's best is
the posterior one, a failed start or a surprising failure is tried again, the best can be confirmed."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

import corl
from corl.errors import InputError
from corl.gp.fitting import fit_regression
from corl.optimizers.safe import P_SURPRISE, SafeBOOptimizer
from corl.problem import Bounds, Outcome

BOX = Bounds(np.array([-1.0, -1.0]), np.array([1.0, 1.0]))


def _disk(x):
    x = np.asarray(x, dtype=float)
    return bool(x @ x < 0.5), float(-np.sum((x - 0.3) ** 2))


@pytest.mark.parametrize("sigma", [0.02, 0.1])
def test_the_fitted_noise_recovers_a_known_noise_level(sigma):
    rng = np.random.default_rng(3)
    X = rng.uniform(-1.0, 1.0, size=(60, 2))
    y = np.sin(2.0 * X[:, 0]) + 0.5 * X[:, 1] ** 2 + sigma * rng.standard_normal(60)
    fit = fit_regression(X, y, BOX)
    assert not fit.fallback
    assert 0.6 * sigma < fit.model.noise_std_ < 1.6 * sigma, (sigma, fit.model.noise_std_)


def test_the_best_is_the_posterior_one_not_a_lucky_reading():
    opt = SafeBOOptimizer(BOX, max_evals=100, seed=0, start=[0.0, 0.0])
    rng = np.random.default_rng(0)
    X = rng.uniform(-0.5, 0.5, size=(25, 2))
    for x in X:  # R = -|x - 0.3|^2 with readings of noise 0.02
        opt.tell(x, Outcome(True, float(-np.sum((x - 0.3) ** 2) + 0.02 * rng.standard_normal())))
    lucky = np.array([0.0, 0.05])  # true R = -0.15, amid the others: one reading of +0.5
    opt.tell(lucky, Outcome(True, 0.5))
    observed, best = opt.best_observed, opt.learners_best
    assert np.array_equal(observed[0], lucky) and observed[1] == 0.5
    assert not np.array_equal(best.theta, lucky)
    true = -np.sum((best.theta - 0.3) ** 2)
    assert true > -0.1 and abs(best.mean - true) < 3 * best.std  # the mean is an estimate of R there
    assert opt.best[1] == best.mean  # what best answers


def test_a_start_read_as_failed_is_tried_again_and_the_run_goes_on():
    readings = iter([False])

    def f(x):
        if next(readings, True) is False:
            return False, None  # one wrong reading of the success sensor
        return _disk(x)

    result = corl.optimize(f, BOX, [0.0, 0.0], budget=30, seed=0)
    assert result.theta is not None and result.failures >= 1
    assert np.sum((result.theta - 0.3) ** 2) < 0.01
    opt = result.optimizer
    X, s = opt._safety_data()
    assert len(X) == len(opt.X_) - 1 and s.all() == bool(np.all(opt.success_[1:]))  # the wrong reading left g_S


def test_a_start_that_fails_every_time_is_refused_after_the_retries():
    with pytest.raises(InputError, match="failed all 3 times it was tried"):
        corl.optimize(lambda x: (False, None), BOX, [0.0, 0.0], budget=30, seed=0)


def test_a_failure_where_the_model_was_sure_is_tried_again_and_leaves_no_hole():
    opt = SafeBOOptimizer(BOX, max_evals=60, seed=1, start=[0.0, 0.0])
    opt.tell([0.0, 0.0], Outcome(*_disk([0.0, 0.0])))
    flipped = False
    while not opt.done:
        x = opt.ask()
        p = opt._asked_p[-1][1] if opt._asked_p else 0.0
        if not flipped and p >= P_SURPRISE:  # one true success read as a failure, where g_S was sure
            opt.tell(x, Outcome(False))
            flipped, where = True, x.copy()
            assert np.array_equal(opt.ask(), where)  # checked once more
            continue
        opt.tell(x, Outcome(*_disk(x)))
    assert flipped
    X, s = opt._safety_data()
    assert not np.any(np.all(X == where, axis=1) & ~s)  # the wrong reading is not in g_S's data
    assert opt.learners_best is not None and np.sum((opt.learners_best.theta - 0.3) ** 2) < 0.01


def test_a_lone_success_among_failures_is_never_the_best():
    opt = SafeBOOptimizer(BOX, max_evals=100, seed=0, start=[0.0, 0.0])
    for x in ([0.0, 0.0], [0.1, 0.0], [0.0, 0.1], [-0.1, 0.0], [0.05, 0.05]):
        opt.tell(x, Outcome(True, 0.0))
    for x in ([0.75, 0.75], [0.9, 0.6], [0.6, 0.9], [0.9, 0.9]):  # failures all around ...
        opt.tell(x, Outcome(False))
    opt.tell([0.75, 0.85], Outcome(True, 5.0))  # ... and a failure read as a success with a high return
    assert opt.best_observed[1] == 5.0
    assert np.linalg.norm(opt.learners_best.theta - [0.75, 0.85]) > 0.3


def test_confirm_repeats_the_best_at_the_end():
    box = corl.Bounds([-1.0, -1.0], [1.0, 1.0])
    settings = replace(corl.OptimizerSettings.for_box(box, fitted=True), confirm=3)
    result = corl.optimize(_disk, box, [0.0, 0.0], budget=40, seed=0, settings=settings)
    X = result.optimizer.X_
    assert np.all(X[-3:] == X[-1]) and np.array_equal(result.theta, X[-1])
    plain = corl.optimize(_disk, box, [0.0, 0.0], budget=40, seed=0)
    assert result.trials == plain.trials + 3 and result.stop_reason is plain.stop_reason
    with pytest.raises(InputError, match="confirm"):
        replace(settings, confirm=-1)


@pytest.mark.parametrize("label_noise", [0.0, 0.05])
def test_with_label_noise_declared_a_stop_that_one_failed_reading_decides_is_checked(label_noise):
    box = Bounds(np.array([0.0]), np.array([4.0]))  # safe below 3.5, R = theta: the optimum on the edge
    opt = SafeBOOptimizer(box, max_evals=40, seed=0, start=[0.5], label_noise=label_noise)
    opt.tell([0.5], Outcome(True, 0.5))
    flipped = None
    while not opt.done:
        x = opt.ask()
        if flipped is None and x[0] > 1.0:  # the first step past 1 is read as a failure, wrongly
            flipped = x.copy()
            opt.tell(x, Outcome(False))
            continue
        opt.tell(x, Outcome(True, float(x[0])) if x[0] < 3.5 else Outcome(False))
    retried = any(np.array_equal(x, flipped) for x in opt.X_[opt.success_])
    if label_noise == 0.0:  # not declared: the wrong reading stands as the edge of the safe set
        assert not retried and opt.learners_best.theta[0] < 1.1
    else:  # declared: the stop rested on that one reading, so it is tried again; the search reaches the edge
        assert retried and 3.3 < opt.learners_best.theta[0] < 3.5
        assert len(opt._checks) <= max(1, int(np.ceil(label_noise * opt.max_evals)))  # within its budget


def test_label_noise_is_checked():
    with pytest.raises(InputError, match="label_noise"):
        SafeBOOptimizer(BOX, label_noise=0.5)
    with pytest.raises(InputError, match="label_noise"):
        corl.OptimizerSettings(label_noise=float("nan"))


def test_a_declared_return_noise_closes_the_gate_where_the_gain_is_within_it():
    from corl.acquisition.safe_ei import NOISE_GATE, SEIB

    opt = SafeBOOptimizer(BOX, max_evals=100, seed=0, start=[0.0, 0.0])
    for x in ([0.0, 0.0], [0.1, 0.0], [0.0, 0.1], [0.15, 0.15], [-0.1, 0.05]):
        opt.tell(x, Outcome(*_disk(x)))
    opt.done  # fits the models of the decision
    plain = opt._acquisition()
    X = np.random.default_rng(0).uniform(-1, 1, size=(4000, 2))
    parts = plain.parts(X)
    gated = parts["band"] & parts["ucb_gate"]
    assert gated.any()  # without a declared noise some band points may beat R^+
    mu, var = plain.regression.predict(X[gated])
    excess = mu + 2.0 * np.sqrt(var) - plain.best_return  # what the gate compares
    sigma = float(np.max(excess)) / NOISE_GATE * 1.01  # a noise whose NOISE_GATE stds exceed every such gain
    noisy = SEIB(plain.regression, plain.classifier, plain.best_return, plain.scale, plain.config,
                 box=plain.box, noise_std=sigma).parts(X)
    assert not (noisy["band"] & noisy["ucb_gate"]).any()
    with pytest.raises(InputError, match="return_noise"):
        SafeBOOptimizer(BOX, return_noise=-1.0)


def test_the_budgets_last_trial_repeats_a_best_in_doubt():
    opt = SafeBOOptimizer(BOX, max_evals=11, seed=0, start=[0.0, 0.0])
    for x in ([0.0, 0.0], [0.1, 0.0], [0.0, 0.1], [-0.1, 0.0], [0.05, 0.05]):
        opt.tell(x, Outcome(True, 0.0))
    for x in ([0.75, 0.75], [0.9, 0.6], [0.6, 0.9], [0.9, 0.9]):
        opt.tell(x, Outcome(False))
    opt.tell([0.75, 0.85], Outcome(True, 5.0))  # a failure read as a success, the highest return by far
    assert opt.n_evals == opt.max_evals - 1
    assert np.array_equal(opt.ask(), [0.75, 0.85])  # tried again with the last trial
    opt.tell([0.75, 0.85], Outcome(False))
    assert opt.done and np.linalg.norm(opt.learners_best.theta - [0.75, 0.85]) > 0.3
