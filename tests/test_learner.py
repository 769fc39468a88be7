import math

import numpy as np
import pytest

from corl.errors import DemonstrationFailedError, InputError, RolloutError, StateError
from corl.methods import make_method
from corl.learner import CORL, CORLConfig
from corl.optimizers.base import BlackBoxOptimizer
from corl.problem import Outcome
from corl.tasks.synthetic import W_OPT, SyntheticTask


class Scripted(BlackBoxOptimizer):
    """Proposes a fixed list of thetas, then stops."""

    def __init__(self, bounds, thetas):
        super().__init__(bounds, max_evals=1000, name="scripted")
        self.queue = [np.atleast_1d(t) for t in thetas]

    def _propose(self):
        return self.queue.pop(0) if self.queue else None


def scripted(thetas):
    return lambda b, x0, rng: Scripted(b, list(thetas))


def fast_config(**kw):
    return CORLConfig(eps_max=0.05, eps_w=1e-6, **kw)


def test_demonstration_is_trial_zero_and_failure_is_reported():
    task = SyntheticTask((-0.5, -0.5))  # theta0 = -2.36: outside the safe region
    learner = CORL(task, scripted([]))
    p = learner.ask()
    assert p.index == 0 and p.step == "demonstration"
    learner.tell(task.rollout(p.w))  # one failed reading may be wrong: the demonstration is tried again (start_retries)
    for k in range(1, learner.config.start_retries + 1):
        again = learner.ask()
        assert again.index == k and again.step == "demonstration" and np.array_equal(again.w, p.w)
        if k < learner.config.start_retries:
            learner.tell(task.rollout(again.w))
    with pytest.raises(DemonstrationFailedError, match="demonstration"):
        learner.tell(task.rollout(again.w))
    assert len(learner.history) == 1 + learner.config.start_retries and learner.done


def test_a_demonstration_read_once_as_failed_is_tried_again_and_the_run_goes_on():
    task = SyntheticTask((0.5, 0.5))
    learner = CORL(task, scripted([0.4, 0.5]), fast_config(max_rounds=1))
    first = learner.ask()
    learner.tell(Outcome(False))  # a wrong reading of the success sensor
    again = learner.ask()
    assert again.step == "demonstration" and np.array_equal(again.w, first.w)
    learner.tell(task.rollout(again.w))
    assert not learner.done and learner.failed_w == []  # the demonstration succeeded: no failed w is kept
    learner.run()
    assert learner.best is not None and learner.stop_reason is not None


def test_tell_without_ask_and_repeated_ask():
    learner = CORL(SyntheticTask((0.5, 0.5)), scripted([]))
    with pytest.raises(StateError, match="ask"):
        learner.tell(Outcome(True, 0.0))
    assert learner.ask() is learner.ask()


def test_a_second_tell_without_an_ask_is_refused_and_the_next_trial_stays_pending():
    task = SyntheticTask((0.5, 0.5))
    learner = CORL(task, scripted([0.4, 0.5]), fast_config(max_rounds=1))
    first = learner.ask()
    learner.tell(task.rollout(first.w))  # works out trial 1 at once, but does not hand it out
    with pytest.raises(StateError, match=r"tell\(\) without a pending ask\(\): call ask\(\) first"):
        learner.tell(Outcome(True, 0.5))
    assert len(learner.history) == 1
    second = learner.ask()
    assert second.index == 1
    learner.tell(task.rollout(second.w))
    assert [p.index for p, _ in learner.history] == [0, 1]


def test_nan_return_is_rejected_before_it_reaches_the_learner():
    learner = CORL(SyntheticTask((0.5, 0.5)), scripted([]))
    learner.ask()
    with pytest.raises(InputError, match="finite"):
        learner.tell(Outcome(True, float("nan")))
    with pytest.raises(InputError):
        learner.tell("yes")
    learner.tell(Outcome(True, 0.5))  # the pending trial is still there and can be answered
    assert len(learner.history) == 1


def test_rollout_that_raises_keeps_the_trial_pending():
    task = SyntheticTask((0.5, 0.5))
    calls = {"n": 0}
    real = task.rollout

    def flaky(w):
        calls["n"] += 1
        if calls["n"] == 3:
            raise RuntimeError("robot e-stop")
        return real(w)

    task.rollout = flaky
    learner = CORL(task, scripted([0.1]), fast_config())
    with pytest.raises(RolloutError, match="stays pending"):
        learner.run()
    pending = learner.ask()
    assert pending.index == 2 and len(learner.history) == 2
    learner.run()
    assert learner.done and [p.index for p, _ in learner.history] == list(range(len(learner.history)))


def test_step_one_respects_trust_region_and_keeps_theta():
    task = SyntheticTask((0.3, 0.4))
    learner = CORL(task, scripted([]), CORLConfig(eps_max=0.01, eps_w=1e-6))
    learner.run()
    opt = [p for p, _ in learner.history if p.step == "optimization"]
    assert len(opt) > 10
    ws = [learner.history[0][0].w] + [p.w for p in opt]
    steps = np.linalg.norm(np.diff(ws, axis=0), axis=1)
    assert np.all(steps <= 0.01 + 1e-9)
    theta0 = math.atan2(0.4, 0.3)
    assert all(abs(math.atan2(p.w[1], p.w[0]) - theta0) < 1e-6 for p in opt)
    assert abs(np.hypot(*learner.best.w) - 1.0) < 1e-3  # converged onto the circle


def test_step_two_uses_eq18_and_takes_the_best_success():
    task = SyntheticTask((0.6, 0.8))
    learner = CORL(task, scripted([0.2, 0.05, 3.0]), fast_config())
    learner.run()
    rl = [(p, o) for p, o in learner.history if p.step == "reinforcement"]
    assert [round(float(p.theta[0]), 6) for p, _ in rl[:3]] == [0.2, 0.05, 3.0]
    for p, _ in rl:  # Eq. 18: the projected w realises theta
        assert abs(math.atan2(p.w[1], p.w[0]) - p.theta[0]) < 1e-5
    assert not rl[2][1].success
    np.testing.assert_allclose(learner.best.theta, [0.05])
    assert np.linalg.norm(learner.best.w - np.array([math.cos(0.05), math.sin(0.05)])) < 1e-3


def test_stops_when_nothing_changes():
    task = SyntheticTask((1.0, 0.0))  # already optimal: J = 0, and the scripted RL proposes nothing
    learner = CORL(task, scripted([]), fast_config())
    learner.run()
    assert learner.done and len(learner.history) == 1 and learner.rounds == 0


def test_theta_step_stop():
    task = SyntheticTask((0.6, 0.8))
    learner = CORL(task, scripted([0.3, 0.301, 0.5, 0.6]), fast_config(theta_step_stop=True, eps_theta=0.003))
    learner.run()
    rl = [p for p, _ in learner.history if p.step == "reinforcement" and p.round == 0]
    assert len(rl) == 2


@pytest.mark.parametrize("w0", [(0.2, 1.2), (-0.3, 1.2), (1.4, -0.9)])
def test_corl_pibu_finds_the_global_optimum_safely(w0):
    learner = make_method("CORL+PIBU", SyntheticTask(w0), seed=0)
    best = learner.run()
    failures = sum(not o.success for _, o in learner.history)
    assert np.linalg.norm(best.w - W_OPT) < 0.05
    assert failures <= 4


def test_a_run_that_ends_at_max_rounds_names_the_black_box_step_that_stopped():
    """Issue 21, part 5: rounds whose step 2 stops by its own rule without moving theta* end with
    that rule's reason, not ``max_rounds`` (more rounds would not help it)."""
    from corl.optimizers.base import StopReason

    class Nothing(Scripted):  # step 2: nothing is worth a trial
        def _propose(self):
            return StopReason.NO_IMPROVEMENT

    task = SyntheticTask((0.6, 0.4))  # |w0| = 0.72: two trust-region steps per round leave w moving
    learner = CORL(task, lambda b, x0, rng: Nothing(b, []), fast_config(max_rounds=2, max_optimization_steps=2))
    learner.run(max_trials=500)
    assert learner.stop_reason is StopReason.NO_IMPROVEMENT
    assert learner.rl_stop_reason is StopReason.NO_IMPROVEMENT
    assert "black-box step of round 1" in learner.stop_detail and "no_improvement" in learner.stop_detail


def test_a_run_whose_last_black_box_step_still_moved_theta_ends_at_max_rounds():
    from corl.optimizers.base import StopReason

    task = SyntheticTask((0.6, 0.4))  # theta0 = 0.588; R grows towards theta = 0
    learner = CORL(task, scripted([0.3]), fast_config(max_rounds=1, max_optimization_steps=2))
    learner.run(max_trials=500)
    assert learner.best.theta[0] == pytest.approx(0.3)
    assert learner.stop_reason is StopReason.MAX_ROUNDS
    assert "max_rounds=1" in learner.stop_detail
