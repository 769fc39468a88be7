"""The synthetic benchmark sweep (Sec. VIII-A, Fig. 1): methods x random feasible starts.

Metrics per run (one method from one start):
* found      : the best successful policy is within ``FOUND_TOLERANCE`` (0.05) of w* = (1, 0);
* failures   : number of trials with S = 0;
* max_dist   : the largest distance in theta from a failed trial to the safe interval
               (-1.5, 2.5); 0 for a run without failures (methods over w use theta = atan2(w2, w1));
* rollouts   : all trials, the demonstration and every step-1 rollout included;
* theta_trials : the trials of the black-box step (CORL) or of the search (methods over w).
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from corl.methods import PAPER_FIG1, MethodSettings, make_method
from corl.settings import PAPER_SYNTHETIC
from corl.tasks.synthetic import W_OPT, SyntheticTask, distance_to_safe

__all__ = ["FOUND_TOLERANCE", "RunMetrics", "starts", "run_one", "sweep", "aggregate"]

FOUND_TOLERANCE = 0.05


@dataclass(frozen=True)
class RunMetrics:
    method: str
    start: int
    found: bool
    failures: int
    max_dist: float
    rollouts: int
    theta_trials: int
    best_w: tuple[float, float] | None
    seconds: float


def starts(n: int, seed: int) -> np.ndarray:
    """``n`` feasible starts (n, 2), uniform in the box, the same for every method."""
    rng = np.random.default_rng([seed, 2016])
    return np.array([SyntheticTask.random_start(rng) for _ in range(n)])


def run_one(method: str, start_index: int, w0: np.ndarray, seed: int,
            settings: MethodSettings = PAPER_SYNTHETIC) -> RunMetrics:
    t0 = time.perf_counter()
    task = SyntheticTask(w0)
    learner = make_method(method, task, seed=seed * 100003 + start_index, settings=settings)
    learner.run(max_trials=5000)
    fails = [p for p, o in learner.history if not o.success]
    dists = [distance_to_safe(float(p.theta[0])) for p in fails]
    best = learner.best
    found = best is not None and float(np.linalg.norm(best.w - W_OPT)) < FOUND_TOLERANCE
    steps = {"reinforcement", "search"}
    return RunMetrics(
        method=method, start=start_index, found=bool(found), failures=len(fails),
        max_dist=max(dists) if dists else 0.0, rollouts=len(learner.history),
        theta_trials=sum(p.step in steps for p, _ in learner.history),
        best_w=None if best is None else (float(best.w[0]), float(best.w[1])),
        seconds=time.perf_counter() - t0,
    )


def sweep(methods, n_starts: int, seed: int, *, jobs: int = 1, backend: str = "loky",
          address: str | None = None, settings: MethodSettings = PAPER_SYNTHETIC,
          progress=None) -> list[RunMetrics]:
    """Every method from the same ``n_starts`` starts, in parallel.

    ``backend`` and ``address`` say where the runs go (:mod:`corl.experiments.backends`: local
    processes, a Ray or a Dask cluster); ``progress(run)`` is called as runs finish. The result is
    sorted by (method, start), the same list whatever the backend.
    """
    from corl.experiments.backends import cluster, run_unordered

    W0 = starts(n_starts, seed)
    tasks = [(m, i, W0[i], seed, settings) for m in methods for i in range(n_starts)]
    results = []
    with cluster(backend, jobs, address):
        for _, r in run_unordered(run_one, tasks, jobs=jobs, backend=backend, batch_size=4):
            results.append(r)
            if progress is not None:
                progress(r)
    order = {m: k for k, m in enumerate(methods)}
    return sorted(results, key=lambda r: (order[r.method], r.start))


def aggregate(results: list[RunMetrics], methods) -> dict[str, dict]:
    """Per-method table rows in the JSON layout of ``synthetic.json``."""
    table = {}
    for m in methods:
        rs = [r for r in results if r.method == m]
        if not rs:
            continue
        f = np.array([r.failures for r in rs], dtype=float)
        d = np.array([r.max_dist for r in rs], dtype=float)
        table[m] = {
            "starts": len(rs),
            "found": int(sum(r.found for r in rs)),
            "failures_mean": float(f.mean()), "failures_std": float(f.std()),
            "max_dist_mean": float(d.mean()), "max_dist_std": float(d.std()),
            "rollouts_mean": float(np.mean([r.rollouts for r in rs])),
            "theta_trials_mean": float(np.mean([r.theta_trials for r in rs])),
            "seconds": float(sum(r.seconds for r in rs)),
            "paper": dict(zip(("found", "failures_mean", "failures_std", "max_dist_mean", "max_dist_std"),
                              PAPER_FIG1.get(m, (None,) * 5))),
        }
    return table
