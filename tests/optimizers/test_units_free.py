"""Issue 25, item 4: every GP method on fitted GPs (what ``corl.optimize`` gives without settings) proposes
the same trials in any unit of the return, ``a R + b`` with a > 0: CORL, PIBU, UCB and SAL. Before, PIBU,
UCB and SAL used fixed GPs in the synthetic benchmark's units, and PIBU stopped after its start when the
returns were around 1e4."""

from __future__ import annotations

import math

import numpy as np
import pytest

import corl
from corl.optimizers.base import failure_score

UNITS = [(1.0, 0.0), (1e4, 0.0), (1e4, -1e5), (1e-3, 0.0), (2.5e-3, 7.5)]


def _peaks_1d(theta):
    x = float(theta[0])
    if not -1.5 < x < 2.5:
        return False, None
    return True, -0.5 * x ** 2 + math.cos(3 * x)


def _ridge_2d(theta):  # not a problem anything was tuned on: a tilted safe ellipse, the best on its rim
    x, y = float(theta[0]), float(theta[1])
    u, v = 0.8 * x + 0.6 * y, -0.6 * x + 0.8 * y
    if (u / 1.2) ** 2 + (v / 0.5) ** 2 > 1.0:
        return False, None
    return True, 0.7 * u - v ** 2 + 0.3 * math.sin(4 * x)


PROBLEMS = {"peaks-1d": (_peaks_1d, ([-math.pi], [math.pi]), [1.8]),
            "ridge-2d": (_ridge_2d, ([-2.0, -2.0], [2.0, 2.0]), [0.0, 0.0])}


@pytest.mark.parametrize("method", ["CORL", "PIBU", "UCB", "SAL"])
@pytest.mark.parametrize("problem", sorted(PROBLEMS))
def test_the_same_trials_in_any_unit_of_the_return(method, problem):
    f, box, start = PROBLEMS[problem]
    width = np.subtract(box[1], box[0])
    runs = []
    for a, b in UNITS:
        def trial(theta, a=a, b=b):
            ok, r = f(theta)
            return ok, None if r is None else a * r + b

        res = corl.optimize(trial, box, start=start, method=method, budget=30, seed=3)
        runs.append((res.trials, res.failures, res.stop_reason, np.asarray(res.theta), (res.return_ - b) / a))
    trials, failures, reason, theta, ret = runs[0]
    assert trials > 3, "the run stopped at its start"
    for other in runs[1:]:
        assert other[:3] == (trials, failures, reason), (method, problem, other[:3], (trials, failures, reason))
        assert np.max(np.abs(other[3] - theta) / width) < 1e-6
        assert abs(other[4] - ret) <= 1e-6 * max(1.0, abs(ret))


def test_a_failure_scores_one_observed_range_below_the_worst_success():
    r = np.array([2.0, -1.0, 0.5])
    assert failure_score(r, None) == -1.0 - 3.0
    assert failure_score(r, -15.0) == -15.0  # a fixed score stays what it was (the paper's presets)
    a, b = 1e4, -3e5  # moves with the returns
    assert failure_score(a * r + b, None) == pytest.approx(a * failure_score(r, None) + b, rel=1e-12)
    assert failure_score(np.array([4.0]), None) == 0.0  # one value: |R| below it
    assert failure_score(np.array([0.0]), None) == -1.0
    assert failure_score(np.array([]), None) == 0.0


def test_the_paper_preset_keeps_its_constant_failure_score():
    box = corl.Bounds(np.array([-math.pi]), np.array([math.pi]))
    assert corl.OptimizerSettings.for_box(box).failure_return == -15.0
    assert corl.OptimizerSettings.for_box(box, fitted=True).failure_return is None
    assert corl.OptimizerSettings().regression.fit_hyperparameters is False


def test_corl_budget_spends_every_trial_in_any_unit_and_never_below_the_band():
    """Issue 25, item 1: CORL(budget) runs its whole budget (stop_reason BUDGET) where CORL stops early."""
    f, box, start = PROBLEMS["peaks-1d"]
    plain = corl.optimize(f, box, start=start, method="CORL", budget=40, seed=0)
    assert plain.trials < 40 and plain.stop_reason is not corl.StopReason.BUDGET
    runs = []
    for a, b in UNITS[:3]:
        def trial(theta, a=a, b=b):
            ok, r = f(theta)
            return ok, None if r is None else a * r + b

        opt = corl.make_optimizer("CORL(budget)", box, start, budget=40, seed=0)
        opt.tell(start, trial(start))
        while not opt.done:
            x = opt.ask()
            acquisition = opt.last_acquisition
            p = acquisition.classifier.predict_proba(np.atleast_2d(x))[0]
            assert p >= opt.seib.p_band - 1e-9  # never below the band
            opt.tell(x, trial(x))
        runs.append((opt.n_evals, int(np.sum(~opt.success_)), np.asarray(opt.best[0])))
    assert runs[0][0] == 40 and opt.stop_reason is corl.StopReason.BUDGET
    assert all(r[:2] == runs[0][:2] and np.allclose(r[2], runs[0][2], atol=1e-9) for r in runs)
    assert runs[0][1] <= plain.failures + 5


@pytest.mark.parametrize("method", ["PIBU", "UCB", "SAL", "CORL", "CMA"])
def test_returns_at_the_edge_of_the_float_range_leave_every_method_asking(method):
    """Finite returns of +-1.7e308: their difference (and a success less a mean of the other sign)
    overflows. PIBU, UCB and SAL raised 'prior_mean must be finite, got nan' at every later ask."""
    from corl.optimizers.registry import make_optimizer

    opt = make_optimizer(method, ([0, 0], [1, 1]), [0.5, 0.5])
    told = [(True, 1.7e308), (True, -1.7e308), (True, 1.7e308), (True, -1.7e308), (False, None), (True, 1.0)]
    asked = 0
    for outcome in told + [(True, 0.5)] * 3:
        if opt.done:
            break
        x = opt.ask()
        assert np.all(np.isfinite(x))
        opt.tell(x, outcome)
        asked += 1
    assert asked >= 5 and (not opt.done or opt.stop_reason is not None)  # asking, or stopped by its own rule
