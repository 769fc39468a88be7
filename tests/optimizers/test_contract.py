"""The stopping contract, once, over every optimizer in the registry and every learner.

Like a storage test suite run over every backend: each test below runs on each subject. A
subject is a black-box optimizer built by :func:`corl.make_optimizer` (every registered name,
so a method registered later is checked too) or a learner (CORL via ``make_method``,
``DirectSearch`` over w), behind one small adapter.

The contract (corl.optimizers.base): ``done`` and ``stop_reason`` are known before ``ask``; a
stop is never an exception from ``ask`` in the loop ``while not s.done: s.ask(); s.tell(...)``;
``ask`` twice returns the pending point; the budget is respected exactly; asking after a stop
is a StateError; bad input is a clear InputError that records nothing.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

import corl
from corl.errors import InputError, StateError
from corl.experiments.methods import MethodSettings, make_method
from corl.learner import CORLConfig
from corl.optimizers.base import ANSWER_TOLERANCE, StopReason
from corl.problem import Bounds, Outcome
from corl.tasks.synthetic import SyntheticTask

BOX = Bounds(np.zeros(2), np.ones(2))
START = np.array([0.3, 0.3])
SAFE = ("PIBU", "PIBU(literal)", "PIBU(budget)", "SAL", "CORL", "CORL(budget)", "SEIB")  # grow the safe set from a success
OPTIMIZERS = tuple(corl.OPTIMIZERS)


def f(x) -> Outcome:
    """Safe below x1 = 0.7; the return peaks at (0.6, 0.6), on the safe side."""
    if x[1] > 0.7:
        return Outcome(False, None)
    margin = 0.7 - float(x[1])
    return Outcome(True, 1.0 - float(np.sum((x - 0.6) ** 2)), {"boundary_distance": margin} if margin < 0.1 else {})


class OptimizerSubject:
    """A black-box optimizer: ``ask() -> x``, ``tell(x, outcome)``."""

    kind = "optimizer"

    def __init__(self, name: str, budget: int) -> None:
        self.name, self.budget = name, budget
        self.inner = corl.make_optimizer(name, BOX, START, budget=budget, seed=0)

    def ask(self):
        return self.inner.ask()

    def answer(self, x) -> None:
        self.inner.tell(x, f(x))

    def same(self, a, b) -> bool:
        return np.array_equal(a, b)

    def trials(self) -> int:
        return self.inner.n_evals


class LearnerSubject:
    """A learner: ``ask() -> Proposal``, ``tell(outcome)``; its budget counts black-box trials."""

    kind = "learner"

    def __init__(self, name: str, budget: int) -> None:
        self.name, self.budget = name, budget
        task = SyntheticTask((0.0, 1.2))
        settings = MethodSettings(corl=CORLConfig(max_rl_trials=budget), direct_budget=budget)
        self.inner = make_method(name, task, seed=0, settings=settings)

    def ask(self):
        return self.inner.ask()

    def answer(self, proposal) -> None:
        self.inner.tell(self.inner.task.rollout(proposal.w))

    def same(self, a, b) -> bool:
        return a is b

    def trials(self) -> int:
        """Black-box trials: CORL's step-2 thetas (unrealisable ones too); every trial over w."""
        if self.name.startswith("CORL+"):
            return sum(p.step == "reinforcement" for p, _ in self.inner.history) + self.inner.unrealisable
        return len(self.inner.history)


SUBJECTS = [("optimizer", n) for n in OPTIMIZERS] + [("learner", n) for n in ("CORL+PIBU", "CORL+CMA", "PIBU", "CMA", "PoWER")]


def build(kind: str, name: str, budget: int = 6):
    return (OptimizerSubject if kind == "optimizer" else LearnerSubject)(name, budget)


def run(s) -> int:
    """The loop the contract promises to end without an exception; returns the asks made."""
    asks = 0
    while not s.inner.done:
        assert s.inner.stop_reason is None  # known before ask: nothing to report while running
        item = s.ask()
        s.answer(item)
        asks += 1
        assert asks < 5000
    return asks


@pytest.fixture(params=SUBJECTS, ids=lambda p: f"{p[0]}:{p[1]}")
def subject_spec(request):
    return request.param


def test_the_loop_ends_without_an_exception_with_a_reason_and_a_best(subject_spec):
    s = build(*subject_spec, budget=40)
    assert not s.inner.done and s.inner.stop_reason is None
    run(s)
    assert isinstance(s.inner.stop_reason, StopReason)
    assert s.inner.done and s.inner.best is not None
    with pytest.raises(StateError, match="has (stopped|finished)"):
        s.inner.ask()  # asking after the stop is the misuse, and it says so
    assert s.inner.done  # and the stop stands


def test_the_budget_is_respected_exactly(subject_spec):
    s = build(*subject_spec, budget=5)
    run(s)
    assert s.trials() <= 5
    if s.inner.stop_reason is StopReason.BUDGET:
        assert s.trials() == 5
    if subject_spec[1] in ("CMA", "PoWER", "PIBU(budget)", "CORL+CMA"):  # no stopping rule fires this early
        assert s.inner.stop_reason is StopReason.BUDGET and s.trials() == 5


def test_each_decision_is_made_once_per_trial(subject_spec):
    # done, stop_reason and ask share one decision: no second GP fit for the same data
    kind, name = subject_spec
    if kind != "optimizer":
        pytest.skip("the learners' optimizers are counted through the optimizer subjects")
    s = build(kind, name, budget=8)
    calls, propose = [], s.inner._propose
    s.inner._propose = lambda: calls.append(1) or propose()
    asks = 0
    while not s.inner.done:
        assert s.inner.stop_reason is None and not s.inner.done
        x = s.ask()
        assert np.array_equal(s.ask(), x)
        s.answer(x)
        asks += 1
    s.inner.stop_reason, s.inner.done  # read again: still no new decision
    # one per trial after the start (the start needs none), one more for a stop the method decides
    assert len(calls) == asks - 1 + (s.inner.stop_reason is not StopReason.BUDGET)


def test_ask_twice_returns_the_pending_point(subject_spec):
    s = build(*subject_spec)
    for _ in range(3):
        first = s.ask()
        assert s.same(first, s.ask())
        s.answer(first)
        if s.inner.done:
            break
        assert not s.same(s.ask(), first)  # told: the next point is a new one


def test_a_told_point_that_differs_by_rounding_answers_the_proposal(subject_spec):
    kind, name = subject_spec
    if kind != "optimizer":
        pytest.skip("a learner's tell takes the outcome of its pending trial, never a point")
    s = build(kind, name, budget=12)
    s.answer(s.ask())  # the start
    for _ in range(4):
        if s.inner.done:
            break
        x = s.ask()
        typed = np.round(x, 4)  # what an operator types: 4 decimals, within the tolerance
        assert np.all(np.abs(typed - x) <= ANSWER_TOLERANCE * BOX.width)
        n = s.inner.n_evals
        s.inner.tell(typed, f(typed))
        assert s.inner.n_evals == n + 1
        if s.inner.done:
            break
        assert not np.array_equal(s.ask(), x)  # a new proposal, not the stale one


def test_bad_input_is_a_clear_error_and_records_nothing(subject_spec):
    kind, name = subject_spec
    s = build(kind, name)
    s.answer(s.ask())
    pending = s.ask()
    n = s.trials()
    if kind == "optimizer":
        with pytest.raises(InputError, match="outside the bounds"):
            s.inner.tell(np.array([1.5, 0.2]), Outcome(True, 1.0))
        with pytest.raises(InputError, match="finite return"):
            s.inner.tell(pending, (True, math.nan))
        with pytest.raises(InputError, match="shape"):
            s.inner.tell(np.zeros(3), Outcome(False))
    else:
        with pytest.raises(InputError):
            s.inner.tell("success")
    assert s.trials() == n and s.same(s.ask(), pending)  # nothing recorded; the trial still pending
    s.answer(pending)  # and it goes on


def test_duplicates_with_conflicting_labels_keep_the_optimizer_usable(subject_spec):
    kind, name = subject_spec
    if kind != "optimizer":
        pytest.skip("a learner tells each of its own trials once")
    s = build(kind, name, budget=20)
    s.answer(s.ask())
    for outcome in (Outcome(True, 0.5), Outcome(False), Outcome(True, 0.4), Outcome(False)):
        s.inner.tell(np.array([0.5, 0.69]), outcome)
    if not s.inner.done:
        x = s.ask()
        assert np.all(np.isfinite(x)) and BOX.contains(x)


def test_an_all_failure_history_stops_a_safe_method_with_a_reason_and_a_success_revives_it(subject_spec):
    kind, name = subject_spec
    if kind != "optimizer":
        pytest.skip("learners start from a demonstration that must succeed (DemonstrationFailedError)")
    s = build(kind, name, budget=20)
    for x in ([0.1, 0.9], [0.5, 0.8], [0.9, 0.95]):
        s.inner.tell(np.array(x), Outcome(False))
    assert np.array_equal(s.ask(), START)  # no success known: the start comes first
    s.inner.tell(START, Outcome(False))  # and fails too
    if name in SAFE:  # a safe method asks a failed start again (start_retries, twice): a reading may be wrong
        for _ in range(s.inner.start_retries):
            assert not s.inner.done and np.array_equal(s.ask(), START)
            s.inner.tell(START, Outcome(False))  # it fails again
        assert s.inner.done and s.inner.stop_reason is StopReason.NO_SAFE_POINT
        with pytest.raises(StateError, match="succeed"):
            s.inner.ask()
        s.inner.tell(np.array([0.2, 0.2]), f(np.array([0.2, 0.2])))  # a success: the method decides again
    assert not s.inner.done and s.inner.stop_reason is None
    assert BOX.contains(s.ask())


def test_a_decision_not_yet_handed_out_is_redone_when_other_data_arrives():
    # PIBU in 2-D draws no random numbers: the same data gives the same point
    a = corl.make_optimizer("PIBU", BOX, START, seed=0)
    b = corl.make_optimizer("PIBU", BOX, START, seed=0)
    for opt in (a, b):
        opt.tell(START, f(START))
    assert not a.done  # decided, not handed out
    extra = np.array([0.3, 0.6])
    for opt in (a, b):
        opt.tell(extra, f(extra))
    np.testing.assert_array_equal(a.ask(), b.ask())
    # once handed out, a proposal stays pending when a different point is told
    x = a.ask()
    a.tell(np.array([0.9, 0.1]), f(np.array([0.9, 0.1])))
    np.testing.assert_array_equal(a.ask(), x)


def test_corl_counts_its_budget_over_all_rounds_and_reports_it():
    learner = make_method("CORL+CMA", SyntheticTask((0.0, 1.2)), seed=0,
                          settings=MethodSettings(corl=CORLConfig(max_rl_trials=7, max_rounds=3)))
    learner.run()
    steps = [p.step for p, _ in learner.history]
    assert steps.count("reinforcement") + learner.unrealisable == 7 == learner.rl_trials
    assert learner.stop_reason is StopReason.BUDGET
