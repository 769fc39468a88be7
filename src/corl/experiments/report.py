"""Plain-text tables of benchmark results, side by side with the paper's numbers."""

from __future__ import annotations

__all__ = ["synthetic_table"]


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
