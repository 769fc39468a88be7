"""Fig. 3 over trials: cumulative failures and best-so-far return from per-trial records."""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest

from corl.experiments.door.curves import run_curves, trial_curves
from corl.experiments.figures import plot_trial_curves
from corl.experiments.tables import curves_table


def _run(method, success, returns, start=0.1, seed=0):
    return SimpleNamespace(method=method, seed=seed, trial_success=np.array(success, dtype=bool),
                           trial_returns=np.array(returns, dtype=float), start_return=start,
                           trials=len(success))


def test_run_curves_count_failures_and_keep_the_best_success():
    run = _run("A", [True, False, True, False], [0.3, math.nan, 0.2, math.nan], start=0.25)
    failures, best = run_curves(run, 6)
    np.testing.assert_array_equal(failures, [0, 1, 1, 2, 2, 2])  # stopped after 4: flat afterwards
    np.testing.assert_allclose(best, [0.3, 0.3, 0.3, 0.3, 0.3, 0.3])
    failures, best = run_curves(_run("A", [False, True], [math.nan, 0.2], start=0.25), 2)
    np.testing.assert_allclose(best, [0.25, 0.25])  # the start counts, a failure never does
    failures, best = run_curves(_run("A", [], [], start=0.25), 3)  # no trial at all
    np.testing.assert_array_equal(failures, [0, 0, 0])
    np.testing.assert_allclose(best, [0.25] * 3)
    _, best = run_curves(_run("A", [True, True, True], [0.1, 0.5, 0.4]), 2)  # budget shorter than the run
    np.testing.assert_allclose(best, [0.1, 0.5])


def test_trial_curves_average_over_seeds_and_print_at_fixed_counts(tmp_path):
    runs = [_run("A", [False, True], [math.nan, 0.4], seed=0), _run("A", [True, True], [0.2, 0.6], seed=1),
            _run("B", [False], [math.nan])]
    curves = trial_curves(runs, ["A", "B", "C"], {"A": 2, "B": 3, "C": 5})
    assert set(curves) == {"A", "B"}  # C has no runs
    np.testing.assert_allclose(curves["A"]["failures_mean"], [0.5, 0.5])
    np.testing.assert_allclose(curves["A"]["failures_std"], [0.5, 0.5])
    np.testing.assert_allclose(curves["A"]["best_mean"], [0.15, 0.5])
    assert curves["B"]["stopped"] == [1] and curves["B"]["k"] == [1, 2, 3]
    text = curves_table(curves, at=(1, 3))
    assert "0.5 ±  0.5 /  0.150" in text and text.splitlines()[-2].split()[-1] == "-"  # A has no k = 3
    path = plot_trial_curves(curves, tmp_path / "curves.png")
    assert path.stat().st_size > 10_000


@pytest.mark.slow
def test_door_runs_carry_their_trials_and_the_true_return():
    pytest.importorskip("mujoco")
    from corl.experiments.door.runs import door_task, run_corl

    run = run_corl("CORL+CMA", 3, 4, task=door_task({}))
    assert run.trial_success.shape == run.trial_returns.shape == (run.trials,)
    assert np.isnan(run.trial_returns[~run.trial_success]).all()
    assert np.isfinite(run.trial_returns[run.trial_success]).all()
    assert run.failures == int((~run.trial_success).sum())
    # without sensor error the returned policy's true R is the best measured one of step 2 or w*'s
    assert run.final_return == pytest.approx(np.nanmax(np.r_[run.start_return, run.trial_returns]), abs=1e-12)
