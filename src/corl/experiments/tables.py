"""Plain-text tables of benchmark results, side by side with the paper's numbers: Fig. 1 (synthetic),
Fig. 3 (door) and the door's curves over trials."""

from __future__ import annotations

import math

import numpy as np

__all__ = ["synthetic_table", "door_table", "curves_table"]


def _pm(mean, std, digits=2) -> str:
    return "-" if mean is None else f"{mean:.{digits}f} ± {std:.{digits}f}"


def synthetic_table(table: dict[str, dict], tolerance: float) -> str:
    """Fig. 1 as text: ours beside the paper's for every method in ``table``."""
    head = (f"{'Method':<20} {'found':>8} {'paper':>8}   {'failures':>13} {'paper':>13}   "
            f"{'max dist':>13} {'paper':>13}   {'rollouts':>9} {'theta trials':>12}")
    lines = [f"Fig. 1, synthetic benchmark (found: best success within {tolerance} of w* = (1, 0);"
             " max dist: largest distance in theta from a failure to (-1.5, 2.5), 0 without failures)",
             head, "-" * len(head)]
    for name, row in table.items():
        p = row["paper"]
        found_p = "-" if p["found"] is None else f"{p['found']}/100"
        lines.append(
            f"{name:<20} {row['found']:>4}/{row['starts']:<3} {found_p:>8}   "
            f"{_pm(row['failures_mean'], row['failures_std']):>13} {_pm(p['failures_mean'], p['failures_std']):>13}   "
            f"{_pm(row['max_dist_mean'], row['max_dist_std']):>13} {_pm(p['max_dist_mean'], p['max_dist_std']):>13}   "
            f"{row['rollouts_mean']:>9.1f} {row['theta_trials_mean']:>12.1f}"
        )
    return "\n".join(lines)


def door_table(table: dict[str, dict], *, iterations: int | None = None, dmp_iterations: int | None = None,
               regions: dict | None = None, force_reference: float | None = None) -> str:
    """Fig. 3 as text: ours beside the paper's for every method in ``table``."""
    budget = "" if iterations is None else f", CORL: 1 round with <= {iterations} black-box trials"
    if dmp_iterations is not None:
        budget += f", DMP+PoWER: {dmp_iterations} trials"
    lines = [f"Fig. 3, door benchmark (Algorithm 1{budget}; mean ± std over seeds)",
             f"  our R = 1 - F / {force_reference:g} N" if force_reference else "  our R",
             "  the paper's R is in other units: compare trends, not values",
             "  max dist: largest Euclidean distance in theta (m) from a failure to the nearest safe grid point"]
    if regions:
        for region in regions.values():
            lines.append(f"  safe region {region.key}: {region.success.shape[0]} x {region.success.shape[1]} grid, "
                         f"{int(region.success.sum())} safe, resolution {np.round(region.spacing, 4).tolist()} m")
    head = (f"{'Method':<11} {'highest R':>15} {'paper':>15}  {'true R':>7}   {'failures':>11} {'trials':>6}   "
            f"{'failure rate':>13} {'paper':>13} {'per budget':>10}   {'max dist':>17} {'paper':>17}   {'start R':>7}")
    lines += [head, "-" * len(head)]
    for name, row in table.items():
        p = row["paper"]
        n_budget = dmp_iterations if name == "DMP+PoWER" else iterations
        per_budget = "-" if n_budget is None else f"{row['failures_mean'] / n_budget:.3f}"
        lines.append(
            f"{name:<11} {_pm(row['highest_return_mean'], row['highest_return_std'], 3):>15} "
            f"{_pm(p['highest_return_mean'], p['highest_return_std'], 3):>15}  {_fmt(row['final_return_mean']):>7}   "
            f"{_pm(row['failures_mean'], row['failures_std'], 1):>11} {row['trials_mean']:>6.1f}   "
            f"{_pm(row['failure_rate_mean'], row['failure_rate_std'], 3):>13} "
            f"{_pm(p['failure_rate_mean'], p['failure_rate_std'], 3):>13} {per_budget:>10}   "
            f"{_pm(row['max_dist_mean'], row['max_dist_std'], 4):>17} "
            f"{_pm(p['max_dist_mean'], p['max_dist_std'], 4):>17}   {_fmt(row['start_return_mean']):>7}"
        )
    lines.append("  true R: the returned policy's R without sensor error (mean over seeds); failure rate: "
                 "failures / trials; per budget: failures / the trial budget")
    if "DMP+PoWER" in table:
        lines.append("  DMP+PoWER: the paper reports no noticeable learning after 150 iterations (no numbers); "
                     "start R is the fitted DMP's return")
    return "\n".join(lines)


def _fmt(value) -> str:
    return "-" if value is None else f"{value:.3f}"


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
