"""Hostile input to the public ask/tell API: every refusal is a one-line corl error that leaves the
state as it was, and the optimizers keep working with any finite return and after pickling.

Each test runs over every optimizer in the registry (:data:`corl.OPTIMIZERS`) where it applies,
and over the learners built by :func:`corl.methods.make_method`.
"""

from __future__ import annotations

import math
import pickle

import numpy as np
import pytest

import corl
from corl.errors import CorlError, InputError, StateError
from corl.gp.fitting import fit_regression
from corl.learner import CORLConfig
from corl.methods import MethodSettings, make_method
from corl.optimizers.base import MODEL_RANGE, StopReason, model_scale
from corl.optimizers.gpconfig import FITTED_CLASSIFIER, FITTED_REGRESSION
from corl.problem import Bounds, Outcome
from corl.tasks.synthetic import SyntheticTask

BOX = Bounds(np.zeros(2), np.ones(2))
START = np.array([0.3, 0.3])
OPTIMIZERS = tuple(corl.OPTIMIZERS)
HUGE = (1e154, 1e300, -1e300, 1.7e308, -1.7e308)  # finite returns whose squares (or sums) overflow


def f(x) -> Outcome:
    """Safe below x1 = 0.7; the return peaks at (0.6, 0.6), on the safe side."""
    if x[1] > 0.7:
        return Outcome(False, None)
    return Outcome(True, 1.0 - float(np.sum((x - 0.6) ** 2)))


def scaled(outcome: Outcome, k: int) -> Outcome:
    """The same outcome with its return multiplied by 2**k (exact)."""
    if not outcome.success:
        return outcome
    return Outcome(True, math.ldexp(float(outcome.return_), k), outcome.info)


def one_line_error(excinfo, *words) -> str:
    message = str(excinfo.value)
    assert "\n" not in message and message
    for word in words:
        assert word in message, f"{word!r} not in {message!r}"
    return message


def snapshot(opt):
    return opt.X_.copy(), opt.success_.copy(), opt.returns_.copy()


def same_snapshot(a, b) -> bool:
    return all(np.array_equal(u, v, equal_nan=True) for u, v in zip(a, b))


@pytest.fixture(params=OPTIMIZERS)
def name(request):
    return request.param


# -- 1. tell() twice without an ask() in between ---------------------------------------------
def test_a_second_answer_without_an_ask_is_refused_and_records_nothing(name):
    opt = corl.make_optimizer(name, BOX, START, budget=10, seed=0)
    x = opt.ask()
    opt.tell(x, f(x))
    before = snapshot(opt)
    with pytest.raises(StateError) as excinfo:
        opt.tell(x, f(x))
    one_line_error(excinfo, "tell() without a pending ask()", "call ask() first")
    assert same_snapshot(snapshot(opt), before)
    opt.done  # the next decision worked out but not handed out: still no second answer
    with pytest.raises(StateError, match="without a pending ask"):
        opt.tell(np.round(x, 4), f(x))  # within rounding of the point told: the same answer
    assert same_snapshot(snapshot(opt), before)
    if not opt.done:  # and the loop goes on
        y = opt.ask()
        opt.tell(y, f(y))
        assert opt.n_evals == 2


def test_data_that_answers_nothing_asked_is_still_welcome(name):
    # the contract: points told up front, a demonstration, another method's trials need no ask()
    opt = corl.make_optimizer(name, BOX, START, budget=10, seed=0)
    for x in ([0.3, 0.3], [0.2, 0.25], [0.2, 0.25]):
        opt.tell(np.array(x), f(np.array(x)))
    x = opt.ask()
    opt.tell(x, f(x))
    other = np.array([0.5, 0.69])
    opt.tell(other, f(other))  # not the point just told: data
    assert opt.n_evals == 5


@pytest.mark.parametrize("method", ["CORL", "CORL+PIBU", "PIBU", "CMA"])
def test_a_learner_refuses_tell_without_a_pending_ask(method):
    task = SyntheticTask((0.0, 1.2))
    learner = make_method(method, task, seed=0, settings=MethodSettings(corl=CORLConfig(max_rl_trials=5),
                                                                        direct_budget=5))
    p = learner.ask()
    learner.tell(task.rollout(p.w))
    n = len(learner.history)
    with pytest.raises(StateError) as excinfo:
        learner.tell(Outcome(True, 0.3))
    one_line_error(excinfo, "tell() without a pending ask()", "call ask() first")
    assert len(learner.history) == n  # nothing recorded for a trial never handed out
    q = learner.ask()
    assert q.index == 1
    learner.tell(task.rollout(q.w))
    assert len(learner.history) == n + 1 and learner.history[-1][0] is q


# -- 2. any finite return ----------------------------------------------------------------------
def test_model_scale_is_one_in_range_and_a_power_of_two_beyond():
    assert model_scale([0.5, -3.0, np.nan]) == 1.0 and model_scale([MODEL_RANGE, -MODEL_RANGE]) == 1.0
    for top in (1e101, 1e154, 1e300, 1.7e308):
        s = model_scale([0.1, -top])
        assert math.frexp(s)[0] == 0.5  # a power of two: dividing by it is exact
        assert MODEL_RANGE / 2 < top / s <= MODEL_RANGE


def test_huge_returns_keep_every_optimizer_asking(name):
    opt = corl.make_optimizer(name, BOX, START, budget=30, seed=0)
    x = opt.ask()
    opt.tell(x, Outcome(True, 0.5))
    for r in HUGE + (0.2, 1e-300):
        if opt.done:  # a stop the method decided is fine; an exception is not
            assert isinstance(opt.stop_reason, StopReason)
            return
        x = opt.ask()
        assert np.all(np.isfinite(x)) and BOX.contains(x)
        opt.tell(x, Outcome(True, r))
    if not opt.done:
        assert BOX.contains(opt.ask())
    assert opt.best_observed[1] == 1.7e308  # the highest reading
    assert np.isfinite(opt.best[1])  # the method's best: for CORL g_R's posterior mean there, finite too


@pytest.mark.parametrize("k", [400, 1000])  # returns up to about 2.6e120 and 1.1e301
def test_corl_proposes_the_same_points_whatever_the_unit_of_the_return(k):
    # SEIB on fitted GPs is free of the return's unit, and a power of two is exact: bit for bit
    def run(k):
        opt = corl.make_optimizer("CORL", BOX, START, budget=12, seed=0)
        points = []
        while not opt.done:
            x = opt.ask()
            points.append(x)
            opt.tell(x, scaled(f(x), k))
        return np.array(points), opt.stop_reason

    plain, reason = run(0)
    huge, huge_reason = run(k)
    np.testing.assert_array_equal(huge, plain)
    assert huge_reason is reason


def test_optimize_with_huge_returns_finds_the_best():
    result = corl.optimize(lambda x: scaled(f(x), 1000), BOX, START, budget=10, seed=0)
    reference = corl.optimize(f, BOX, START, budget=10, seed=0)
    np.testing.assert_array_equal(result.theta, reference.theta)
    assert result.return_ == math.ldexp(reference.return_, 1000)


def test_the_corl_learner_learns_the_same_with_huge_returns():
    task = SyntheticTask((0.0, 1.2))
    settings = MethodSettings(regression=FITTED_REGRESSION, classifier=FITTED_CLASSIFIER,
                              corl=CORLConfig(max_rl_trials=6, max_rounds=2))

    def run(k):
        learner = make_method("CORL", task, seed=0, settings=settings)
        while not learner.done:
            p = learner.ask()
            learner.tell(scaled(task.rollout(p.w), k))
        return learner

    plain, huge = run(0), run(1000)
    steps = [p.step for p, _ in plain.history]
    assert "reinforcement" in steps and [p.step for p, _ in huge.history] == steps
    for (p, _), (q, _) in zip(huge.history, plain.history):
        np.testing.assert_array_equal(p.theta, q.theta)
    assert huge.stop_reason is plain.stop_reason


def test_fit_regression_refuses_returns_it_cannot_hold_in_their_units():
    X = np.array([[0.1, 0.1], [0.5, 0.5], [0.9, 0.2]])
    with pytest.raises(InputError) as excinfo:
        fit_regression(X, np.array([1e200, -1e200, 0.0]), BOX)
    one_line_error(excinfo, "divide them")


# -- 3. arguments that are not what they should be ----------------------------------------------
@pytest.mark.parametrize("seed", [-1, "abc", 1.5, True, [1, 2]])
def test_make_optimizer_refuses_a_bad_seed(seed):
    with pytest.raises(InputError) as excinfo:
        corl.make_optimizer("UCB", BOX, START, seed=seed)
    one_line_error(excinfo, "seed")


def test_make_optimizer_takes_the_seeds_it_documents():
    for seed in (None, 0, np.int64(7), np.random.default_rng(1)):
        corl.make_optimizer("PoWER", BOX, START, seed=seed).ask()


@pytest.mark.parametrize("start", ["x", {"a": 1}, [0.3, "y"], None])
def test_make_optimizer_refuses_a_start_that_is_not_a_point(name, start):
    with pytest.raises(InputError) as excinfo:
        corl.make_optimizer(name, BOX, start)
    one_line_error(excinfo, "start")


def test_make_optimizer_refuses_settings_of_another_type():
    with pytest.raises(InputError) as excinfo:
        corl.make_optimizer("UCB", BOX, START, settings={"ucb_kappa": 1.0})
    one_line_error(excinfo, "settings", "dict")
    with pytest.raises(InputError) as excinfo:
        corl.make_optimizer(None, BOX, START)
    one_line_error(excinfo, "unknown optimizer")


@pytest.mark.parametrize("x", ["abc", {"a": 1}, [0.1, "x"], None, [0.1, 0.2, 0.3]])
def test_tell_refuses_a_point_that_is_not_one_and_records_nothing(name, x):
    opt = corl.make_optimizer(name, BOX, START, budget=10, seed=0)
    pending = opt.ask()
    with pytest.raises(InputError):
        opt.tell(x, Outcome(True, 1.0))
    assert opt.n_evals == 0
    np.testing.assert_array_equal(opt.ask(), pending)


@pytest.mark.parametrize("outcome", [(True, 10**400), ("yes", 1.0), (True, "abc"), None, (True,)])
def test_tell_refuses_an_outcome_that_is_not_one_and_records_nothing(name, outcome):
    opt = corl.make_optimizer(name, BOX, START, budget=10, seed=0)
    pending = opt.ask()
    with pytest.raises(InputError) as excinfo:
        opt.tell(pending, outcome)
    one_line_error(excinfo)
    assert opt.n_evals == 0
    opt.tell(pending, f(pending))  # the pending point is still there to answer


@pytest.mark.parametrize("distance", ["abc", math.nan, math.inf, None, [1, 2]])
def test_sal_refuses_a_boundary_distance_that_is_not_a_number(distance):
    opt = corl.make_optimizer("SAL", BOX, START, budget=10, seed=0)
    x = opt.ask()
    if distance is None:
        opt.tell(x, Outcome(True, 1.0, {"boundary_distance": None}))  # None means "not measured"
        return
    with pytest.raises(InputError) as excinfo:
        opt.tell(x, Outcome(True, 1.0, {"boundary_distance": distance}))
    one_line_error(excinfo, "boundary_distance")
    assert opt.n_evals == 0 and opt.safety_.size == 0
    opt.tell(x, Outcome(True, 1.0, {"boundary_distance": 0.01}))  # the trial is still there to answer
    assert opt.n_evals == 1 and opt.safety_.size == 1


@pytest.mark.parametrize("method, words", [(None, "unknown method"), (3, "unknown method"),
                                           ("CORL+NOPE", "NOPE")])
def test_make_method_refuses_a_bad_name(method, words):
    with pytest.raises(InputError) as excinfo:
        make_method(method, SyntheticTask((0.0, 1.2)))
    one_line_error(excinfo, words)


@pytest.mark.parametrize("seed", [-1, "abc", 1.5, None])
def test_make_method_refuses_a_bad_seed(seed):
    with pytest.raises(InputError) as excinfo:
        make_method("CORL", SyntheticTask((0.0, 1.2)), seed=seed)
    one_line_error(excinfo, "seed")


def test_make_method_refuses_settings_of_another_type():
    with pytest.raises(InputError) as excinfo:
        make_method("CORL", SyntheticTask((0.0, 1.2)), settings={"direct_budget": 3})
    one_line_error(excinfo, "settings", "dict")


# -- 4. pickling ---------------------------------------------------------------------------------
def test_every_optimizer_pickles_after_ask_and_after_tell_and_goes_on_the_same(name):
    opt = corl.make_optimizer(name, BOX, START, budget=12, seed=0)
    for _ in range(4):
        if opt.done:
            break
        x = opt.ask()
        copy = pickle.loads(pickle.dumps(opt))  # after ask: the point is pending in both
        np.testing.assert_array_equal(copy.ask(), x)
        for o in (opt, copy):
            o.tell(x, f(x))
        copy = pickle.loads(pickle.dumps(opt))  # after tell: the next decision is the same
        assert copy.done == opt.done
        if opt.done:
            assert copy.stop_reason is opt.stop_reason
            break
        np.testing.assert_array_equal(copy.ask(), opt.ask())


def test_no_raw_exception_leaks_from_the_refusals():
    # every refusal above is a CorlError that is also the builtin a caller may catch
    assert issubclass(InputError, CorlError) and issubclass(InputError, ValueError)
    assert issubclass(StateError, CorlError) and issubclass(StateError, RuntimeError)


@pytest.mark.parametrize("task", [None, 3, "synthetic"])
def test_make_method_refuses_a_task_that_is_none(task):
    with pytest.raises(InputError) as excinfo:
        make_method("CORL", task)
    one_line_error(excinfo, "make_method's task", "is not a task")


def test_a_learner_run_refuses_a_callback_that_is_no_function():
    learner = make_method("CORL", SyntheticTask((0.0, 1.2)))
    with pytest.raises(InputError) as excinfo:
        learner.run(callback=3)
    one_line_error(excinfo, "callback must be a function")
    assert learner.history == []
