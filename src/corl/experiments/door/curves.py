"""Fig. 3 over trials: failures and best return as a method spends its budget.

The paper's table gives one number per method after the whole budget. A method that stops early
(PIBU by its own rule) and one that spends every trial (CMA-ES) are then compared over different
trial counts; these curves compare them at every count. Their text is
:func:`corl.experiments.tables.curves_table`, their figure :func:`corl.experiments.figures.plot_trial_curves`.

Glossary
--------
k         : trials spent, 1 .. budget
failures  : failed trials among the first k (a run that stopped earlier stays at its total)
best      : the highest measured R among the first k trials and the policy the black-box step
            starts from (a run that stopped earlier keeps its last value)
"""

from __future__ import annotations

import numpy as np

__all__ = ["run_curves", "trial_curves"]


def run_curves(run, budget: int) -> tuple[np.ndarray, np.ndarray]:
    """Cumulative failures and best-so-far R of one :class:`DoorRun` over ``k = 1 .. budget``, (budget,) each."""
    success = np.asarray(run.trial_success, dtype=bool)[:budget]
    returns = np.asarray(run.trial_returns, dtype=float)[:budget]
    failures = np.cumsum(~success)
    best = np.fmax.accumulate(np.concatenate([[run.start_return], returns]))[1:]  # NaN (failure) never wins
    pad = budget - len(success)
    if pad > 0:  # stopped early: no more trials, nothing changes
        failures = np.concatenate([failures, np.full(pad, failures[-1] if len(failures) else 0)])
        best = np.concatenate([best, np.full(pad, best[-1] if len(best) else run.start_return)])
    return failures.astype(float), best


def trial_curves(runs, methods, budgets: dict[str, int]) -> dict[str, dict]:
    """Mean and std over seeds of :func:`run_curves` per method; ``budgets[method]`` trials each.

    Returns ``{method: {"k": [...], "failures_mean", "failures_std", "best_mean", "best_std",
    "stopped": [trials of each run]}}`` (lists, ready for JSON).
    """
    curves = {}
    for m in methods:
        rs = [r for r in runs if r.method == m]
        if not rs:
            continue
        budget = int(budgets[m])
        F, B = zip(*(run_curves(r, budget) for r in rs))
        F, B = np.vstack(F), np.vstack(B)
        with np.errstate(invalid="ignore"):
            best_mean, best_std = np.nanmean(B, axis=0), np.nanstd(B, axis=0)
        curves[m] = {"k": list(range(1, budget + 1)), "failures_mean": F.mean(axis=0).tolist(),
                     "failures_std": F.std(axis=0).tolist(), "best_mean": best_mean.tolist(),
                     "best_std": best_std.tolist(), "stopped": [int(r.trials) for r in rs]}
    return curves
