import math

import numpy as np
import pytest

from corl.errors import InputError, StateError
from corl.optimizers.base import StopReason
from corl.optimizers.bo import BOConfig, PIBUOptimizer, StopRule, UCBOptimizer
from corl.optimizers.sal import SALConfig, SALOptimizer
from corl.problem import Bounds, Outcome
from corl.tasks.synthetic import distance_to_safe, return_of

BOUNDS = Bounds([-math.pi], [math.pi])


def evaluate(theta, with_distance=False):
    t = float(theta[0])
    if not -1.5 < t < 2.5:
        return Outcome(False, None)
    info = {}
    margin = min(t + 1.5, 2.5 - t)
    if with_distance and margin < 0.5:
        info["boundary_distance"] = margin
    return Outcome(True, return_of(t), info)


def drive(opt, start, budget=60, with_distance=False):
    opt.tell(np.array([start]), evaluate([start], with_distance))
    while not opt.done and opt.n_evals < budget:  # the contract: no exception when the method stops
        x = opt.ask()
        opt.tell(x, evaluate(x, with_distance))
    return opt


@pytest.mark.parametrize("start", [1.8, -1.2, 0.7])
def test_pibu_finds_the_optimum_with_few_near_boundary_failures(start):
    opt = drive(PIBUOptimizer(BOUNDS, seed=0), start)
    x, r = opt.best
    assert abs(x[0]) < 0.02 and r > 0.99
    fails = opt.X_[~opt.success_, 0]
    assert len(fails) <= 3
    assert all(distance_to_safe(t) < 0.3 for t in fails)
    assert opt.done  # stopped by its own rule, not the budget
    assert opt.n_evals < 40


def test_pibu_stop_rule_near_sampled():
    opt = drive(PIBUOptimizer(BOUNDS, seed=0), 0.5)
    assert opt.done and opt.stop_reason is StopReason.CONVERGED
    with pytest.raises(StateError, match="converged"):
        opt.ask()


def test_pibu_stops_with_no_improvement_when_its_acquisition_is_zero():
    # one success hemmed in by failures every 0.15: no inner region (p < 0.55 even there) and no
    # uncertain stretch of boundary left
    opt = PIBUOptimizer(BOUNDS, seed=0)
    opt.tell(np.array([0.0]), Outcome(True, 1.0))
    for x in np.linspace(-3.0, 3.0, 41):
        if x != 0.0:
            opt.tell(np.array([x]), Outcome(False))
    assert opt.done and opt.stop_reason is StopReason.NO_IMPROVEMENT
    with pytest.raises(StateError, match="no point is worth a trial"):
        opt.ask()


def test_ask_twice_returns_the_pending_point_and_theta_out_of_bounds_is_rejected():
    opt = PIBUOptimizer(BOUNDS, seed=0)
    opt.tell(np.array([0.5]), evaluate([0.5]))
    a = opt.ask()
    np.testing.assert_array_equal(a, opt.ask())
    with pytest.raises(InputError, match="outside the bounds"):
        opt.tell(np.array([4.0]), Outcome(False))
    with pytest.raises(InputError, match="shape"):
        opt.tell(np.array([0.1, 0.2]), Outcome(False))
    assert opt.n_evals == 1  # nothing was recorded by the bad tells


def test_duplicate_points_are_fine():
    opt = PIBUOptimizer(BOUNDS, seed=0)
    for _ in range(5):
        opt.tell(np.array([0.5]), evaluate([0.5]))
    x = opt.ask()
    assert np.all(np.isfinite(x))


def test_ucb_models_failures_with_the_penalty_and_improves():
    opt = drive(UCBOptimizer(BOUNDS, BOConfig(stop_rule=StopRule.SMALL_STEP, stop_distance=3e-3), seed=0), 1.8)
    x, r = opt.best
    assert abs(x[0]) < 0.05
    assert (~opt.success_).sum() >= 2  # it does not care about safety


def test_sal_uses_the_boundary_distance_and_stays_safe():
    opt = drive(SALOptimizer(BOUNDS, SALConfig(), seed=0), 1.8, with_distance=True)
    x, r = opt.best
    assert abs(x[0]) < 0.05
    fails = opt.X_[~opt.success_, 0]
    assert len(fails) <= 2
    assert np.any(opt.safety_ < SALConfig().critical_distance)  # distances were observed


def test_stop_distance_is_measured_in_the_scaled_units():
    from corl.optimizers.bo import _stop

    X = np.array([[0.0, 0.0]])
    x = np.array([0.0005, 0.0005])  # 0.7 mm away in raw units
    assert _stop(StopRule.NEAR_SAMPLED, x, X, 1e-3)
    # the second axis counts 10x (its length scales are 10x shorter): now 5 mm away
    assert not _stop(StopRule.NEAR_SAMPLED, x, X, 1e-3, (1.0, 0.1))
    assert not _stop(StopRule.SMALL_STEP, x, X, 1e-3, (1.0, 0.1))
    assert not _stop(StopRule.BUDGET, x, X, 1e-3)
    with pytest.raises(InputError, match="3 entries"):
        _stop(StopRule.NEAR_SAMPLED, x, X, 1e-3, (1.0, 1.0, 1.0))


def test_configs_validate():
    with pytest.raises(InputError, match="distance_scale"):
        BOConfig(distance_scale=(1.0, 0.0))
    assert BOConfig(distance_scale=[1, 2]).distance_scale == (1.0, 2.0)
    with pytest.raises(InputError):
        BOConfig(stop_distance=-1)
    with pytest.raises(InputError):
        SALConfig(alpha=1.5)
    with pytest.raises(ValueError):
        BOConfig(stop_rule="sometimes")


def test_a_subclass_whose_propose_returns_none_stops_converged():
    # the hook subclasses of the BO base use: None from _propose means "stop", never an exception
    from corl.optimizers.bo import _BayesOpt

    class StopsAtThree(_BayesOpt):
        def _acquisition(self):
            return None

        def _propose(self):
            return None if self.n_evals >= 3 else super()._propose()

    opt = StopsAtThree(BOUNDS, BOConfig(), max_evals=10, seed=0, name="three")
    asked = 0
    while not opt.done:
        x = opt.ask()
        opt.tell(x, evaluate(x))
        asked += 1
    assert asked == 3 and opt.stop_reason is StopReason.CONVERGED
