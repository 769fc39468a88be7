"""Fig. 3 over trials: failures and best return as a method spends its budget.

The paper's table gives one number per method after the whole budget. A method that stops early
(PIBU by its own rule) and one that spends every trial (CMA-ES) are then compared over different
trial counts; these curves compare them at every count.

Glossary
--------
k         : trials spent, 1 .. budget
failures  : failed trials among the first k (a run that stopped earlier stays at its total)
best      : the highest measured R among the first k trials and the policy the black-box step
            starts from (a run that stopped earlier keeps its last value)
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

__all__ = ["run_curves", "trial_curves", "curves_table", "plot_trial_curves"]


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


def curves_table(curves: dict[str, dict], at=(10, 25, 40, 60, 100)) -> str:
    """The curves at a few trial counts, as text: failures and best R (mean ± std over seeds)."""
    lines = ["Over trials (failures so far / highest R so far, mean ± std over seeds; a run that stopped "
             "keeps its totals):"]
    head = f"{'Method':<11} " + " ".join(f"{f'k = {k}':>24}" for k in at)
    lines += [head, "-" * len(head)]
    for m, c in curves.items():
        cells = []
        for k in at:
            if k > len(c["k"]):
                cells.append(f"{'-':>24}")
                continue
            i = k - 1
            b = c["best_mean"][i]
            best = "-" if b is None or not math.isfinite(b) else f"{b:.3f}"
            cells.append(f"{c['failures_mean'][i]:5.1f} ± {c['failures_std'][i]:4.1f} / {best:>6}".rjust(24))
        lines.append(f"{m:<11} " + " ".join(cells))
    return "\n".join(lines)


def plot_trial_curves(curves: dict[str, dict], path: str | Path) -> Path:
    """Two panels over trials k: failures so far and highest R so far, mean ± std band per method."""
    from corl.experiments.figures import _pyplot, _save

    plt = _pyplot()
    fig, (ax_f, ax_r) = plt.subplots(1, 2, figsize=(10, 4))
    for m, c in curves.items():
        k = np.asarray(c["k"])
        for ax, key in ((ax_f, "failures"), (ax_r, "best")):
            mean = np.asarray(c[f"{key}_mean"], dtype=float)
            std = np.asarray(c[f"{key}_std"], dtype=float)
            line, = ax.plot(k, mean, label=m)
            ax.fill_between(k, mean - std, mean + std, color=line.get_color(), alpha=0.2)
        stops = np.asarray(c["stopped"])
        if stops.max() < len(k):  # mark where the runs stopped by their own rule
            ax_f.axvline(float(np.mean(stops)), color=line.get_color(), ls=":", lw=1,
                         label=f"{m} stops (mean {np.mean(stops):.0f} trials)")
    ax_f.set(xlabel="trials", ylabel="failures so far", title="Failures (Fig. 3 over trials)")
    ax_r.set(xlabel="trials", ylabel="highest R so far", title="Highest return")
    ax_f.legend(loc="upper left")
    ax_f.grid(alpha=0.3)
    ax_r.grid(alpha=0.3)
    return _save(plt, fig, path)
