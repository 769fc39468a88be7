"""The door benchmark of Sec. VIII-B, Fig. 3: CORL+PIBU, CORL+CMA and DMP+PoWER on the door task,
every seed of every method, then the safe regions and the table (``corl bench door``).

Glossary
--------
theta        : (2,) grasp shift along the handle (m) and finger width (m), the door's theta
safe region  : the thetas whose realisation (Eq. 18 from an anchor trajectory) opens the door,
               measured on a grid over ``task.theta_bounds`` (:func:`safe_region`)
anchor       : the trajectory a theta is realised from; for CORL the ``w*`` its black-box step
               starts from (the result of the motion-optimization step), for DMP+PoWER the
               demonstration
R            : the door task's return ``1 - F / 20 N`` (F the mean wrist force); the paper's R is
               in other units, so only the trend compares
trial        : one rollout of the black-box step (CORL's step 2, PoWER's search)

Metrics of one run (the rows of Fig. 3; mean and standard deviation over seeds):

* highest return : the largest R over every successful rollout of the run (demonstration and
  motion-optimization rollouts included: they are the policy the learner starts from);
* failure rate   : failed trials / trials of the black-box step;
* max distance   : the largest Euclidean distance in theta (m, both coordinates unscaled) from a
  failed trial to the nearest safe grid point; 0 for a run without failures.

Setup of the runs (beyond the paper, which states no budget for the door):

* CORL runs the full Algorithm 1 for one round (``CORLConfig(max_rounds=1)``): motion
  optimization from the demonstration, then at most ``iterations`` black-box trials. PIBU may
  stop earlier by its own rule (its next point within 1e-3 of a sampled one).
* A theta the projection cannot realise is told to the black-box method as a failure without a
  rollout (see :mod:`corl.learner`); those are counted apart (``unrealisable``), not as failures.
* DMP+PoWER: PoWER over the 96 parameters of a DMP fitted to the demonstration
  (:mod:`corl.experiments.door.dmp`); its theta is measured on the executed reference, and its
  trajectory is not a projection from the anchor, so its distance to the safe region is only
  indicative.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from corl.errors import InputError
from corl.experiments.backends import check_backend, cluster, run_unordered
from corl.experiments.door.curves import trial_curves
from corl.experiments.door.dmp import run_dmp_power
from corl.experiments.door.runs import CORL_METHODS, DoorRun, Progress, digest, door_task, run_corl, task_settings
from corl.experiments.door.safe_region import SafeRegion, distance_to_safe, safe_region

__all__ = ["DOOR_METHODS", "PAPER_FIG3", "DoorBench", "run_one", "door_sweep", "aggregate"]

DOOR_METHODS = CORL_METHODS + ("DMP+PoWER",)
PAPER_FIG3 = {  # highest return (mean, std), failure rate (mean, std), max distance (mean, std)
    "CORL+PIBU": (0.45, 0.032, 0.157, 0.021, 0.0146, 0.006),
    "CORL+CMA": (0.41, 0.017, 0.190, 0.102, 0.0358, 0.030),
}


def run_one(method: str, seed: int, iterations: int, dmp_iterations: int = 150,
            settings: dict | None = None) -> DoorRun:
    """One run of a Fig. 3 row (``method`` in :data:`DOOR_METHODS`) in this process's DoorTask."""
    task = door_task(settings or {})
    if method == "DMP+PoWER":
        return run_dmp_power(seed, dmp_iterations, task=task)
    return run_corl(method, seed, iterations, task=task)


# -- the sweep and the table -----------------------------------------------------------------------
@dataclass(frozen=True)
class DoorBench:
    """Runs, the safe regions they were measured against (by anchor key) and the table rows."""

    runs: list[DoorRun]
    regions: dict[str, SafeRegion]
    table: dict[str, dict]
    curves: dict[str, dict]  # failures and best R over trials (:func:`corl.experiments.door.curves.trial_curves`)


def door_sweep(methods, seeds: int, iterations: int = 100, *, out: str | Path | None = None,
               dmp_iterations: int = 150, grid: tuple[int, int] = (25, 15), jobs: int = 2,
               backend: str = "loky", address: str | None = None, progress: Progress | None = None,
               force_noise: float = 0.0) -> DoorBench:
    """Every method from seeds ``0 .. seeds - 1``, then the safe regions and the table.

    ``force_noise`` (N) adds a seeded error to the force measurement behind R (``DoorTask``), so
    that seeds differ as they would on a robot; S, and so the safe region, stays exact.

    ``jobs``, ``backend`` and ``address`` say where the runs and the safe-region grids go (local
    processes, a Ray or a Dask cluster: :func:`corl.experiments.backends.cluster`, opened once).

    The safe region of a run is realised from that run's anchor (CORL: ``w*`` after motion
    optimization, the same for every seed; DMP+PoWER: the demonstration); each distinct anchor's
    grid is computed once and cached in ``out``.
    """
    methods = list(methods)
    check_backend(backend, address)
    unknown = [m for m in methods if m not in DOOR_METHODS]
    if unknown:
        raise InputError(f"unknown door method(s) {', '.join(unknown)}; choose from {', '.join(DOOR_METHODS)}")
    if seeds < 1 or iterations < 1 or dmp_iterations < 1:
        raise InputError("seeds, iterations and dmp_iterations must be at least 1")
    task = door_task({})
    settings = task_settings(task)
    def seeded(s: int) -> dict:  # each seed its own measurement error; exact without noise
        return {**settings, "force_noise": float(force_noise), "seed": s} if force_noise > 0 else settings

    jobs_list = [(m, s, iterations, dmp_iterations, seeded(s)) for m in methods for s in range(seeds)]
    runs = []
    regions: dict[str, SafeRegion] = {}
    with cluster(backend, jobs, address):
        for _, r in run_unordered(run_one, jobs_list, jobs=jobs, backend=backend):
            runs.append(r)
            if progress is not None:
                progress("runs", len(runs), len(jobs_list), f"{r.method} seed {r.seed}: {r.failures}/{r.trials} failed",
                         run=r)
        order = {m: k for k, m in enumerate(methods)}
        runs.sort(key=lambda r: (order[r.method], r.seed))
        for r in runs:
            key = digest(r.anchor)
            if key not in regions:
                anchor_task = door_task({**settings, "contact_times": r.anchor_times})
                regions[key] = safe_region(anchor_task, *grid, anchor=r.anchor, cache=out, jobs=jobs,
                                              backend=backend, progress=progress)
    budgets = {m: dmp_iterations if m == "DMP+PoWER" else iterations for m in methods}
    return DoorBench(runs, regions, aggregate(runs, regions, methods), trial_curves(runs, methods, budgets))


def _max_distance(run: DoorRun, region: SafeRegion) -> float:
    return max((distance_to_safe(t, region) for t in run.failed_thetas), default=0.0)


def _mean_std(values) -> tuple[float, float]:
    v = np.asarray(values, dtype=float)
    v = v[np.isfinite(v)]
    return (float(v.mean()), float(v.std())) if v.size else (math.nan, math.nan)


def aggregate(runs: list[DoorRun], regions: dict[str, SafeRegion], methods) -> dict[str, dict]:
    """Per-method rows of ``door.json``: mean and population std over seeds.

    A NaN (``first_return`` of a run whose first trial failed) is left out of its mean; a row
    without any finite value reads None.
    """
    table = {}
    for m in methods:
        rs = [r for r in runs if r.method == m]
        if not rs:
            continue
        region = {id(r): regions[digest(r.anchor)] for r in rs}
        rows = {
            "highest_return": [r.highest_return for r in rs],
            "failure_rate": [r.failures / r.trials if r.trials else 0.0 for r in rs],
            "max_dist": [_max_distance(r, region[id(r)]) for r in rs],
            "final_return": [r.final_return for r in rs],
            "failures": [r.failures for r in rs],
            "start_return": [r.start_return for r in rs],
            "first_return": [r.first_return for r in rs],
        }
        entry: dict = {"seeds": len(rs)}
        for name, values in rows.items():
            entry[f"{name}_mean"], entry[f"{name}_std"] = _mean_std(values)
        entry.update({
            "trials_mean": float(np.mean([r.trials for r in rs])),
            "unrealisable_total": int(sum(r.unrealisable for r in rs)),
            "rollouts_mean": float(np.mean([r.rollouts for r in rs])),
            "seconds": float(sum(r.seconds for r in rs)),
            "safe_region": sorted({region[id(r)].key for r in rs}),
            "per_seed": [{"seed": r.seed, "highest_return": r.highest_return, "final_return": r.final_return,
                          "failures": r.failures,
                          "trials": r.trials, "max_dist": _max_distance(r, region[id(r)]),
                          "best_theta": None if r.best_theta is None else r.best_theta.tolist()} for r in rs],
            "paper": dict(zip(("highest_return_mean", "highest_return_std", "failure_rate_mean", "failure_rate_std",
                               "max_dist_mean", "max_dist_std"), PAPER_FIG3.get(m, (None,) * 6))),
        })
        table[m] = _json_safe(entry)
    return table


def _json_safe(value):
    """NaN and inf become None (JSON has neither)."""
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, dict):
        return {k: _json_safe(v) for k, v in value.items()}
    if isinstance(value, list):
        return [_json_safe(v) for v in value]
    return value
