"""Speculation in CORL: the next step-1 / phase candidate is computed while a trial runs, and the
trials stay bit for bit those of the sequential learner (corl.learner.CORL._speculate)."""

import threading

import numpy as np
import pytest

import corl.learner as learner_module
import corl.trajectory.phase as phase_module
from corl.learner import CORL, CORLConfig
from corl.problem import Outcome
from test_learner_phase import Nothing, WaypointTask

SPECULATION = "corl-speculation"


def make(task, **config):
    cfg = CORLConfig(eps_max=0.5, eps_w=1e-6, max_rounds=1, max_optimization_steps=30, max_phase_steps=10, **config)
    return CORL(task, lambda b, x0, rng: Nothing(b), cfg)


def drive(learner, rollout):
    """ask / rollout / tell until done; returns [(index, step, w, theta, success, return)]."""
    while not learner.done:
        p = learner.ask()
        learner.tell(rollout(p))
    return [(p.index, p.step, p.w, p.theta, o.success, o.return_) for p, o in learner.history]


def same(a, b):
    assert len(a) == len(b)
    for x, y in zip(a, b):
        assert x[:2] == y[:2] and x[4:] == y[4:]
        assert np.array_equal(x[2], y[2]) and np.array_equal(x[3], y[3])


def succeed(p):
    return Outcome(True, float(-p.index))


def run_both(rollout=succeed):
    sequential = drive(make(WaypointTask()), rollout)
    learner = make(WaypointTask())
    learner.speculative = True
    return sequential, drive(learner, rollout), learner


def test_speculation_gives_the_same_trials_bit_for_bit():
    sequential, speculative, _ = run_both()
    steps = [t[1] for t in speculative]
    assert steps.count("optimization") >= 3 and steps.count("phase") >= 2, steps
    same(sequential, speculative)


def test_the_successor_is_computed_while_the_trial_runs(monkeypatch):
    """The rollout (main thread) waits until a speculation thread has finished a solve / a phase step
    from exactly the proposed w: the successor runs concurrently with the trial."""
    calls = []  # (thread name, step kind, w it starts from)
    solve, optimize_phase = learner_module.solve, phase_module.optimize_phase

    def spy_solve(problem, w, **kwargs):
        result = solve(problem, w, **kwargs)
        calls.append((threading.current_thread().name, "optimization", w))
        return result

    def spy_phase(spline, w, **kwargs):
        result = optimize_phase(spline, w, **kwargs)
        calls.append((threading.current_thread().name, "phase", w))
        return result

    monkeypatch.setattr(learner_module, "solve", spy_solve)
    monkeypatch.setattr(phase_module, "optimize_phase", spy_phase)
    learner = make(WaypointTask())
    learner.speculative = True
    overlapped = []

    def rollout(p):  # runs in the main thread, between ask and tell
        if p.step in ("optimization", "phase") and learner._speculation is not None:
            thread = learner._speculation._thread
            thread.join(10.0)  # the trial is "out" until the successor is done: it ran meanwhile
            assert not thread.is_alive(), "no speculation ran while the trial was out"
            name, kind, w = calls[-1]
            assert name == SPECULATION and w is p.w  # the successor, from exactly this trial's w
            overlapped.append(kind)
        return succeed(p)

    drive(learner, rollout)
    assert "optimization" in overlapped and "phase" in overlapped
    assert learner._speculation is None or not learner._speculation._thread.is_alive()


def test_a_failed_trial_drops_the_speculation():
    def fail_some(p):
        return Outcome(False, None) if p.index in (3, 8) else succeed(p)  # one step-1 trial, one phase trial

    sequential, speculative, learner = run_both(fail_some)
    same(sequential, speculative)
    assert {t[1] for t in speculative if not t[4]} >= {"optimization"}
    assert threading.active_count() == 1 or all(t.name != SPECULATION for t in threading.enumerate())


@pytest.mark.parametrize("where", ["optimization", "phase"])
def test_an_error_of_the_successor_is_raised_where_the_sequential_code_raises_it(monkeypatch, where):
    def run(speculative):
        count = {"n": 0}
        target = learner_module if where == "optimization" else phase_module
        name = "solve" if where == "optimization" else "optimize_phase"
        real = getattr(target, name)

        def flaky(*args, **kwargs):
            count["n"] += 1
            if count["n"] == 3:
                raise FloatingPointError(f"solver broke in {where}")
            return real(*args, **kwargs)

        monkeypatch.setattr(target, name, flaky)
        learner = make(WaypointTask())
        learner.speculative = speculative
        with pytest.raises(FloatingPointError, match=f"solver broke in {where}"):
            drive(learner, succeed)
        monkeypatch.setattr(target, name, real)
        return [(p.index, p.step, p.w) for p, _ in learner.history], learner

    (seq, _), (spec, learner) = run(False), run(True)
    assert [x[:2] for x in seq] == [x[:2] for x in spec] and all(np.array_equal(a[2], b[2]) for a, b in zip(seq, spec))
    assert learner.done  # the error ended the run, as it does without speculation


def test_not_speculative_by_default():
    learner = make(WaypointTask())
    assert learner.speculative is False
    for _ in range(3):  # the demonstration, then step-1 trials
        learner.tell(succeed(learner.ask()))
    assert learner.ask().step == "optimization" and learner._speculation is None
